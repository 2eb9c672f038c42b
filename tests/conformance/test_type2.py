"""Type II conformance over real TCP against real emulator processes: the suite as CTC against
an IXL, and as an IXL client against the CTC; each Type II variant caught by its case."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest

from ktcs_bench.codec.profile import get_profile
from ktcs_bench.conformance import CaseVerdict, SuiteTiming, run_suite
from ktcs_bench.conformance.type2_cases import TYPE2_CASES
from ktcs_bench.emulator.variants import FAULTS

from .conftest import Proc, cli, free_port

PROFILE = get_profile("ktcs-type2")
TIMING = SuiteTiming.resolve(PROFILE)


def _junit(path: Path) -> ET.Element:
    suite = ET.parse(path).getroot().find("testsuite")
    assert suite is not None
    return suite


def test_ixl_passes_every_case(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    port = free_port()
    junit = tmp_path / "ixl.xml"
    # the suite listens as the CTC; the IXL (started right after) connects with back-off
    suite = spawn("conformance", "--role", "ixl", "--target", f"listen://127.0.0.1:{port}",
                  "--station", "18", "--junit", str(junit), wait=False)  # fmt: skip
    spawn("emulator", "ixl", "--station", "18", "--link", f"ctc=tcp://127.0.0.1:{port}")
    assert suite.p.wait(60) == 0, suite.stderr()
    ts = _junit(junit)
    expected = [c.name for c in TYPE2_CASES if "ixl" in c.roles]
    assert [tc.get("name") for tc in ts.iter("testcase")] == expected
    assert ts.get("failures") == "0" and ts.get("errors") == "0"


def test_ctc_passes_every_case(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    ctc = spawn("emulator", "ctc", "--listen", "127.0.0.1:0")
    junit = tmp_path / "ctc.xml"
    run = cli("conformance", "--role", "ctc", "--target", f"tcp://{ctc.ready['listen']}",
              "--station", "20", "--junit", str(junit))  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    ts = _junit(junit)
    assert int(ts.get("tests", "0")) == sum("ctc" in c.roles for c in TYPE2_CASES)
    assert ts.get("failures") == "0"


@pytest.mark.parametrize("variant", sorted(n for n, v in FAULTS.items() if v.kind == "ixl"))
def test_ixl_variant_caught(spawn: Callable[..., Proc], variant: str) -> None:
    port = free_port()
    spawn("emulator", "ixl", "--station", "18", "--link", f"ctc=tcp://127.0.0.1:{port}",
          "--fault", variant)  # fmt: skip
    case = FAULTS[variant].caught_by
    suite = run_suite("ixl", f"listen://127.0.0.1:{port}", PROFILE, TIMING, cases=[case],
                      station=18, codes=75)  # fmt: skip
    (result,) = suite.results
    assert result.verdict is CaseVerdict.FAIL, (result.message, result.evidence.checks)


def test_ctc_variant_caught(spawn: Callable[..., Proc]) -> None:
    ctc = spawn("emulator", "ctc", "--listen", "127.0.0.1:0", "--fault", "accept-unknown-station")
    suite = run_suite("ctc", f"tcp://{ctc.ready['listen']}", PROFILE, TIMING,
                      cases=["t2-refused-station"], station=18)  # fmt: skip
    (result,) = suite.results
    assert result.verdict is CaseVerdict.FAIL
    assert "IDENT sub 2" in result.message


def test_fault_of_another_kind_is_a_usage_error() -> None:
    run = cli("emulator", "ctc", "--fault", "no-nak")
    assert run.returncode == 2 and "do not apply" in run.stderr
