"""Type I conformance against real emulator processes on real ptys: the correct ATC and IXL pass
every case; each fault variant is caught by the case named for it."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ktcs_bench.codec.profile import get_profile
from ktcs_bench.conformance import CaseVerdict, SuiteTiming, run_suite
from ktcs_bench.conformance.type1_cases import TYPE1_CASES
from ktcs_bench.emulator.variants import FAULTS

from .conftest import Proc, cli

TYPE1_VARIANTS = sorted(n for n, v in FAULTS.items() if v.kind == "type1")


def test_atc_passes_every_case_with_junit(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    atc = spawn("emulator", "atc", "--station", "18", "--link", "ixl=pty", "--unpaced")
    junit = tmp_path / "atc.xml"
    run = cli("conformance", "--role", "atc", "--target", atc.ready["ptys"]["ixl"],
              "--station", "18", "--unpaced", "--junit", str(junit))  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    assert "PASSED" in run.stdout and "\x1b[" not in run.stdout  # no colour off a tty
    root = ET.parse(junit).getroot()
    suite = root.find("testsuite")
    assert suite is not None
    assert int(suite.get("tests", "0")) == len(TYPE1_CASES)
    assert suite.get("failures") == "0" and suite.get("errors") == "0"
    names = [tc.get("name") for tc in suite.iter("testcase")]
    assert names == [c.name for c in TYPE1_CASES]
    out = suite.find("testcase/system-out")
    assert (
        out is not None
        and "suite>device" in (out.text or "")
        and "device>suite" in (out.text or "")
    )


def test_ixl_type1_side_json(spawn: Callable[..., Proc]) -> None:
    """The suite plays the ATC on an IXL's Type I endpoint; --json keeps every frame."""
    ixl = spawn("emulator", "ixl", "--station", "20", "--link", "atc=pty", "--unpaced")
    cases = ["request-all", "duplicate-seq", "crc-error-nak", "retry-limit"]
    run = cli("conformance", "--role", "ixl", "--target", ixl.ready["ptys"]["atc"],
              "--station", "20", "--unpaced", "--json", *(a for c in cases for a in ("--case", c)))  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    report = json.loads(run.stdout)
    assert report["summary"]["pass"] == len(cases)
    request_all = next(c for c in report["cases"] if c["name"] == "request-all")
    assert any("32 statuses" in c for c in request_all["checks"])  # st20 ixl_to_atc: 32 codes
    frames = request_all["frames"]
    assert {f["direction"] for f in frames} == {"suite>device", "device>suite"}
    assert all(f["time"] >= 0 and f["hex"].startswith("02") for f in frames)


@pytest.fixture(scope="module")
def variant_atcs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Proc]]:
    """One ATC per Type I variant, all started at once (their start-up overlaps)."""
    folder = tmp_path_factory.mktemp("variants")
    procs = {v: Proc(["emulator", "atc", "--station", "18", "--link", "ixl=pty", "--unpaced",
                      "--fault", v], folder / f"{v}.log") for v in TYPE1_VARIANTS}  # fmt: skip
    try:
        for p in procs.values():
            p.wait_ready()
        yield procs
    finally:
        for p in procs.values():
            p.stop()


@pytest.mark.parametrize("variant", TYPE1_VARIANTS)
def test_variant_caught(variant_atcs: dict[str, Proc], variant: str) -> None:
    atc = variant_atcs[variant]
    profile = get_profile("ktcs-type1")
    case = FAULTS[variant].caught_by
    suite = run_suite("atc", atc.ready["ptys"]["ixl"], profile,
                      SuiteTiming.resolve(profile, line_rate=None), cases=[case], station=18,
                      codes=12)  # fmt: skip
    (result,) = suite.results
    assert result.verdict is CaseVerdict.FAIL, (result.message, result.evidence.checks)
    assert result.evidence.records, "the failing case keeps its frames as evidence"


def test_trackside_subset_and_exit_codes(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    io = spawn("emulator", "trackside", "--station", "22", "--link", "ixl=pty", "--unpaced")
    run = cli("conformance", "--role", "trackside", "--target", io.ready["ptys"]["ixl"],
              "--station", "22", "--unpaced", "--case", "framing", "--case", "request-all")  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    assert "54 statuses" in run.stdout or "PASS  request-all" in run.stdout
    # usage: a Type I role on a TCP target; an unknown case
    assert cli("conformance", "--role", "atc", "--target", "tcp://127.0.0.1:1").returncode == 2
    bad_case = cli("conformance", "--role", "atc", "--target", "/dev/null", "--case", "nope")
    assert bad_case.returncode == 2 and "unknown case" in bad_case.stderr
    # peer/I-O failure: nothing at that serial path
    missing = cli("conformance", "--role", "atc", "--target", str(tmp_path / "no-such-tty"))
    assert missing.returncode == 3, missing.stdout + missing.stderr


@pytest.mark.parametrize(("station", "peer"), [(20, "west"), (18, "east")])
def test_the_suite_plays_the_neighbouring_ixl_on_an_interval_link(
    spawn: Callable[..., Proc], station: int, peer: str
) -> None:
    """SPEC §6.6: a real IXL's interval link is tested like its ATC link -- the suite plays the
    neighbouring IXL, every Type I case, the IXL's ALL_INFO sized by its chart to that side."""
    from ktcs_bench.station.loader import load_line
    from ktcs_bench.station_codes.stations import station_chart

    ixl = spawn("emulator", "ixl", "--station", str(station), "--link", f"{peer}=pty",
                "--unpaced")  # fmt: skip
    run = cli("conformance", "--role", "ixl", "--peer", peer, "--target", ixl.ready["ptys"][peer],
              "--station", str(station), "--unpaced", "--json")  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    report = json.loads(run.stdout)
    assert report["summary"]["pass"] == len(TYPE1_CASES)
    codes = len(station_chart(load_line().view(station), f"ixl_to_{peer}").codes)
    request_all = next(c for c in report["cases"] if c["name"] == "request-all")
    assert any(f"{codes} statuses" in c for c in request_all["checks"]), request_all["checks"]
