"""The suite keeps silent while it times the device, reports the timers it measured, and with
`--timings auto` measures them first. The device is our ATC emulator on a real pty, paced at
9600 bit/s and configured like the independent peer that found the defect (issue 12): ΔR 1.64 s,
sized by a 1024-byte maximum frame, so longer than its 1 s link-test period."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from ktcs_bench.codec.profile import get_profile
from ktcs_bench.conformance import CaseVerdict, SuiteTiming, run_suite
from ktcs_bench.conformance.model import Case, CaseContext
from ktcs_bench.conformance.runner import CASES
from ktcs_bench.lab.topology import resolve_lab_path
from ktcs_bench.type1.config import LinkConfig

from .conftest import Proc, cli

PROFILE = get_profile("ktcs-type1")
PEER = LinkConfig(longest_frame_data=None).resolve(PROFILE)  # what the peer-like ATC runs on


def _peer_lab(folder: Path) -> Path:
    """The reference lab with ΔR sized by the profile's maximum frame (1024 DATA bytes)."""
    ref = resolve_lab_path("reference")
    raw = yaml.safe_load(ref.read_text())
    raw["line"] = str((ref.parent / raw["line"]).resolve())
    raw["timetable"] = str((ref.parent / raw["timetable"]).resolve())
    raw["type1"]["longest_frame_data"] = None
    lab = folder / "peer.yaml"
    lab.write_text(yaml.safe_dump(raw))
    return lab


def _peer_atc(spawn: Callable[..., Proc], folder: Path) -> str:
    atc = spawn("emulator", "atc", "--lab", str(_peer_lab(folder)), "--station", "18",
                "--link", "ixl=pty")  # fmt: skip
    return str(atc.ready["ptys"]["ixl"])


def _properties(junit: Path) -> dict[str, str]:
    root = ET.parse(junit).getroot()
    return {p.get("name", ""): p.get("value", "") for p in root.iter("property")}


def test_peer_timings_are_what_the_issue_names() -> None:
    assert 1.63 < PEER.delta_r < 1.65 and PEER.link_test_period == 1.0


def test_delta_r_longer_than_link_test_passes_without_a_byte_from_the_suite(
    spawn: Callable[..., Proc], tmp_path: Path
) -> None:
    target = _peer_atc(spawn, tmp_path)
    junit = tmp_path / "report.xml"
    run = cli("conformance", "--role", "atc", "--target", target, "--station", "18",
              "--longest-frame", "1024", "--case", "delta-r-nak", "--json", "--junit", str(junit))  # fmt: skip
    report = json.loads(run.stdout)
    (case,) = report["cases"]
    assert run.returncode == 0 and case["verdict"] == "pass", (case["checks"], run.stderr)
    frames = case["frames"]
    start = next(i for i, f in enumerate(frames) if f["summary"].startswith("first 4 bytes"))
    nak = next(i for i, f in enumerate(frames) if f["summary"].startswith("NAK"))
    between = frames[start + 1 : nak]
    # The device sent a data frame while it timed ΔR (its LINK_TEST, or its REQUEST_ALL after
    # the link came up) -- the ACK the suite used to send is what the peer read as the rest of
    # our frame. The suite held it back until the NAK.
    assert any(f["direction"] == "device>suite" and not f["summary"].startswith("ACK")
               for f in between), frames  # fmt: skip
    assert all(f["direction"] == "device>suite" for f in between), between
    assert "reason 2" in frames[nak]["summary"]
    held = [f for f in frames[nak:] if "held while silent" in f["summary"]]
    assert held and held[0]["direction"] == "suite>device"
    # The measured ΔR is reported, and it is the peer's (a timer fires late under load, never early).
    measured = report["measured"]["delta_r"]
    assert PEER.delta_r * 0.95 <= measured <= PEER.delta_r + 0.75
    assert float(_properties(junit)["measured.delta_r"]) == measured


def test_a_case_that_breaks_its_own_silence_is_inconclusive(
    spawn: Callable[..., Proc], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A suite that sends while it times the device's silence has broken the case's premise:
    error (inconclusive), never fail -- and the run goes on."""

    def talks_while_timing(ctx: CaseContext) -> None:
        w = ctx.wire
        w.settle()
        w.send_raw(w.codec.encode(w.next_seq(), w.op["LINK_TEST"])[:4])
        with w.silent("the device times ΔR"):
            w.send_raw(w.codec.encode(w.next_seq(), w.op["LINK_TEST"]))
        ctx.check(False, "never reached")

    monkeypatch.setitem(CASES, "talks-while-timing",
                        Case("talks-while-timing", "type1", "breaks its premise", "-",
                             talks_while_timing))  # fmt: skip
    atc = spawn("emulator", "atc", "--station", "18", "--link", "ixl=pty", "--unpaced")
    suite = run_suite("atc", atc.ready["ptys"]["ixl"], PROFILE,
                      SuiteTiming.resolve(PROFILE, line_rate=None),
                      cases=["talks-while-timing", "unknown-opcode"], station=18)  # fmt: skip
    by_name = {r.case.name: r for r in suite.results}
    broken, after = by_name["talks-while-timing"], by_name["unknown-opcode"]
    assert broken.verdict is CaseVerdict.ERROR, broken.message
    assert broken.message.startswith("inconclusive: the suite sent LINK_TEST"), broken.message
    assert suite.stopped is None and after.verdict is CaseVerdict.PASS


def test_timings_auto_measures_the_peer(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    """No timing given (the suite assumes the SPEC default for a 132-byte frame, ΔR 0.24 s):
    `--timings auto` measures the peer's own and judges by them, so delta-r-nak passes."""
    target = _peer_atc(spawn, tmp_path)
    junit = tmp_path / "auto.xml"
    run = cli("conformance", "--role", "atc", "--target", target, "--station", "18",
              "--timings", "auto", "--case", "delta-r-nak", "--junit", str(junit), timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    assert re.search(r"PASS\s+measure-timings", run.stdout) and re.search(
        r"PASS\s+delta-r-nak", run.stdout
    )
    line = next(x for x in run.stdout.splitlines() if x.startswith("measured: "))
    got = re.fullmatch(r"measured: ΔR (\d+) ms, ACK timeout (\d+) ms, link-test period "
                       r"([\d.]+) s, retry count (\d+)", line)  # fmt: skip
    assert got, line
    delta_r, ack, period = int(got[1]) / 1000, int(got[2]) / 1000, float(got[3])
    assert PEER.delta_r * 0.95 <= delta_r <= PEER.delta_r + 0.75
    assert PEER.ack_timeout * 0.95 <= ack <= PEER.ack_timeout + 0.75
    assert 0.95 <= period <= 1.0 + 0.75
    assert int(got[4]) == PEER.max_transmissions - 1 == 3
    props = _properties(junit)
    assert props["timings"] == "auto" and props["measured.retry_count"] == "3"
    # the cases were judged by the measured figures, not the assumed 0.24 s
    assert abs(float(props["delta_r"]) - delta_r) < 0.2


def test_timings_auto_measures_a_ctc(spawn: Callable[..., Proc]) -> None:
    """Type II: the heartbeat period and T_MAX of our CTC (1 s, 3 s), measured first."""
    ctc = spawn("emulator", "ctc", "--listen", "127.0.0.1:0")
    t2 = get_profile("ktcs-type2")
    suite = run_suite("ctc", f"tcp://{ctc.ready['listen']}", t2, SuiteTiming.resolve(t2),
                      cases=["t2-heartbeat"], station=20, auto=True)  # fmt: skip
    measure, heartbeat = suite.results
    assert measure.case.name == "measure-timings" and measure.verdict is CaseVerdict.PASS, (
        measure.evidence.checks
    )
    assert heartbeat.verdict is CaseVerdict.PASS
    m = suite.measured
    assert m.heartbeat_period is not None and 0.95 <= m.heartbeat_period <= 1.0 + 0.75
    assert m.t2_t_max is not None and 0.95 * 3.0 <= m.t2_t_max <= 3.0 + 0.75
    assert suite.timing.t2_t_max == pytest.approx(m.t2_t_max, abs=0.5)
