"""`lab simulate` runs the lab invariants throughout (issue 23 §3, SPEC §11): every violation is
a line on stderr as it is found and an entry of `violations` in summary.json, and a run that
found any exits 1; the rails' own words for a trailed point or a derailment count too."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from ktcs_bench.datafiles import data_dir
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.lab.invariants import LabSnapshot, SafetyChecker, Violation, rails_violation
from ktcs_bench.lab.safety import Replay
from ktcs_bench.station import load_line

LINE = load_line()
SAFETY_LAB = data_dir("emulators") / "labs" / "safety.yaml"
WARM_UP_S = 8.0

# A wrong-side failure: station 18's platform track circuit fails clear under the train standing
# there, the interlocking sets the home route into it, and the train behind runs in on it.
FAILS_CLEAR = Replay(
    "safety",
    seed=1,
    warm_up_s=WARM_UP_S,
    steps=(
        {"do": "tc_fault", "tc": "TC1855", "kind": "failed_clear", "run_s": 1.0},
        {"do": "route", "station": 18, "entry": "01", "exit": "11", "action": "set"}
        | {"run_s": 60.0},
    ),
)


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", *args],
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def _summary(out: Path) -> dict[str, Any]:
    summary: dict[str, Any] = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    return summary


def _look(time: float, *events: tuple[float, str]) -> LabSnapshot:
    return LabSnapshot(time, {}, frozenset(), {}, {}, tuple(events))


def test_the_rails_trailed_point_and_derailed_events_are_violations_of_invariant_3() -> None:
    """Fed straight to the checker: each counted once (the next look's log still carries it),
    any other event of the rails is none."""
    checker = SafetyChecker(LINE)
    trailed = (10.0, "trailed point 18 31 by train 1001")
    assert checker.feed(_look(10.0, (9.0, "TC1851=1"), trailed)) == [
        Violation(3, "trailed_point", "18/31", 10.0,
                  "train trailed point 31 of station 18: trailed point 18 31 by train 1001"),
    ]  # fmt: skip
    derailed = (11.5, "derailed 20 32")
    found = checker.feed(_look(12.0, trailed, derailed))
    assert [(v.invariant, v.kind, v.where, v.time) for v in found] == [
        (3, "derailed", "20/32", 11.5)
    ]
    assert checker.feed(_look(13.0, trailed, derailed)) == []
    assert rails_violation(1.0, "occupancy TC1851=1") is None
    assert rails_violation(1.0, "point 31 trailed") is None  # the rails' words, not any like them


def test_lab_simulate_of_the_reference_lab_breaks_no_invariant(tmp_path: Path) -> None:
    """Both timetable trains on the line (1003 enters at 120 s), ARS setting their routes."""
    run = _cli("lab", "simulate", "reference", "--for", "200", "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    summary = _summary(tmp_path)
    assert summary["violations"] == [], summary["violations"]
    assert "0 violation(s) of the lab invariants" in run.stdout, run.stdout
    assert "violation" not in run.stderr, run.stderr
    assert summary["trains"]["train1003"]["state"] != "waiting", summary["trains"]


def test_a_track_circuit_failing_clear_under_a_standing_train_is_a_violation_and_exit_1(
    tmp_path: Path,
) -> None:
    """The wrong-side failure through `lab simulate` (its --replay runs the steps): invariant 1
    in summary.json and on stderr as it happened, exit 1."""
    path = FAILS_CLEAR.write(tmp_path / "fails_clear.json")
    out = tmp_path / "run"
    run = _cli("lab", "simulate", "--replay", str(path), "--out", str(out))
    assert run.returncode == 1, (run.stdout, run.stderr)
    violations = _summary(out)["violations"]
    shared = [v for v in violations if (v["invariant"], v["kind"]) == (1, "shared_track_circuit")]
    assert shared and shared[0]["where"] == "TC1855", violations
    assert set(shared[0]) == {"time", "invariant", "kind", "where", "text"}
    assert WARM_UP_S + 1.0 < shared[0]["time"] < WARM_UP_S + 61.0, shared
    lines = [ln for ln in run.stderr.splitlines() if ln.startswith("!! violation: ")]
    assert any("invariant 1 (shared_track_circuit) at TC1855" in ln for ln in lines), run.stderr


def test_a_lasting_violation_is_reported_once_when_it_appears() -> None:
    """In one process, as `lab simulate` runs it: each violation is heard as it is found, and two
    trains standing in one track circuit look after look are one violation."""
    heard: list[tuple[float, Violation]] = []
    lab = InProcessLab(SAFETY_LAB, seed=1, invariants=True,
                       on_violation=lambda v: heard.append((lab.now(), v)))  # fmt: skip

    async def main(lab: InProcessLab) -> int:
        await lab.sleep(WARM_UP_S)
        fail = {"cmd": "fail", "tc": "TC1855", "kind": "failed_clear"}
        assert (await lab.device("tc", fail))["ok"]
        await lab.sleep(1.0)  # the interlocking reads the track circuit clear
        route = {"cmd": "route", "station": 18, "entry": "01", "exit": "11", "action": "set"}
        assert (await lab.device("ctc", route))["ok"]
        await lab.sleep(90.0)
        assert lab.watch is not None
        return lab.watch.checker.looks

    looks = lab.run(main)
    assert looks > 20, looks
    shared = [v for _, v in heard if v.kind == "shared_track_circuit"]
    assert len(shared) == 1 and shared[0].where == "TC1855", heard
    assert all(abs(at - v.time) < 1e-6 for at, v in heard), heard  # heard when it was found
    assert lab.watch is not None and lab.watch.reported == [v for _, v in heard]


def test_a_trailed_point_in_the_rails_log_is_a_violation_as_soon_as_it_is_logged() -> None:
    """The hook for the rails that move trains by the blades (SPEC §6.7): whatever logs it, the
    track-circuit emulator's `trailed point ST P` is a violation of invariant 3 at that moment,
    read from its log."""
    heard: list[Violation] = []
    lab = InProcessLab("reference", invariants=True, on_violation=heard.append)

    async def main(lab: InProcessLab) -> float:
        await lab.sleep(5.0)
        lab.objects["tc"].note("point", "trailed point 20 32")
        at = lab.now()
        await lab.sleep(5.0)
        return at

    at = lab.run(main)
    assert [(v.invariant, v.kind, v.where) for v in heard] == [(3, "trailed_point", "20/32")], heard
    assert heard[0].time == at and "trailed point 20 32" in heard[0].text
