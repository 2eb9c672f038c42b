"""`lab invariants hold`: the lab safety invariants (`lab.invariants`, docs/system_safety.md)
looked at every sample of a procedure's run. Real in-process runs through `ktcs-bench test run`
on the search's lab (`emulators/labs/safety.yaml`: train 2003 standing at station 18's platform,
2005 coming on behind it)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.procedure.model import load_procedure

SAFETY = data_dir("emulators") / "labs" / "safety.yaml"
FAILS_CLEAR = f"""\
id: fails-clear
title: a track circuit failing clear under a standing train lets the train behind run into it
verifies: [SYS-SAFE-01]
setup: {{lab: '{SAFETY}'}}
always:
  - lab invariants hold
steps:
  - fault: tc TC1855 failed_clear
    note: a wrong-side failure under train 2003, standing at the platform
  - wait until: ixl 18 tc TC1855 is clear
    within: 10s
  - ctc: route set 18 01 11
    note: the interlocking sets the home route into the platform it takes for clear
  - wait: 120s
"""


def run(tmp_path: Path, text: str) -> tuple[int, dict[str, Any], str]:
    path = tmp_path / "p.yaml"
    path.write_text(text, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "test", "run", str(path),
         "--json"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    doc = json.loads(done.stdout)["procedures"][0] if done.stdout.strip() else {}
    return done.returncode, doc, done.stderr


@pytest.mark.requirement("SYS-SAFE-01", "SYS-SAFE-02")
def test_lab_invariants_hold_breaks_when_a_train_runs_into_another(tmp_path: Path) -> None:
    """Every step passes -- the route is set, the wait runs -- but train 2005 runs into 2003 on
    the failed track circuit: `always: lab invariants hold` fails the procedure, naming the
    invariant, the track circuit and the time, and the report lists every violation found."""
    code, doc, err = run(tmp_path, FAILS_CLEAR)
    assert code == 1, err
    assert [s["verdict"] for s in doc["steps"]] == ["pass"] * 4
    assert doc["verdict"] == "fail"
    [broken] = doc["broken"]
    route_set = doc["steps"][2]["start_s"]
    assert broken["expectation"] == "lab invariants hold" and broken["t_s"] > route_set
    assert "invariant 1 (shared_track_circuit) at TC1855: trains 2003 and 2005" in broken["seen"]
    assert doc["message"].startswith("always: lab invariants hold broken at")
    found = {(v["invariant"], v["kind"], v["where"]) for v in doc["violations"]}
    assert {(1, "shared_track_circuit", "TC1855"), (2, "train_rear", "2005->2003")} <= found
    assert all(v["time"] >= broken["t_s"] for v in doc["violations"])


@pytest.mark.requirement("SYS-SAFE-01", "SYS-SAFE-02")
def test_lab_invariants_hold_through_the_same_run_without_the_fault(tmp_path: Path) -> None:
    """The same procedure with the track circuit sound: the route into the occupied platform
    is refused, 2005 waits behind the home signal, and the invariants hold at every sample --
    also as a step's expectation held throughout."""
    fault = FAILS_CLEAR[FAILS_CLEAR.index("  - fault:") : FAILS_CLEAR.index("  - wait until:")]
    text = FAILS_CLEAR.replace(fault, "").replace(
        "is clear\n    within: 10s\n", "is occupied\n    within: 10s\n"
    )
    text = text.replace("  - ctc: route set 18 01 11\n", "  - ctc: route set 18 01 11\n"
                        "    refused: occupied\n")  # fmt: skip
    text = text.replace("  - wait: 120s\n", "  - expect: lab invariants hold\n    holds: 120s\n")
    code, doc, err = run(tmp_path, text)
    assert code == 0, (err, doc.get("message"))
    assert doc["broken"] == [] and doc["violations"] == []
    assert doc["steps"][-1]["message"] == "held 120 s"


QUIET = data_dir("emulators") / "procedures" / "labs" / "quiet.yaml"
PLACED_ANEW = f"""\
id: placed-anew
title: a train the procedure moves, put somewhere else, has not run there
verifies: [SYS-SAFE-02]
setup:
  lab: '{QUIET}'
  trains: [{{id: T1, head: TC1851, length_m: 40}}]
always:
  - lab invariants hold
steps:
  - train: T1 place TC2247
    note: beyond two stations with no route set -- run there, it would have passed their signals
  - wait: 2s
  - train: T1 run to 12100 at 80
    note: run on into station 22 with no route set, past a signal at stop
"""


def test_a_train_placed_anew_has_not_run_there_but_one_run_past_a_signal_has(
    tmp_path: Path,
) -> None:
    code, doc, err = run(tmp_path, PLACED_ANEW)
    assert code == 1, err
    assert [s["verdict"] for s in doc["steps"]] == ["pass"] * 3
    [broken] = doc["broken"]
    assert broken["t_s"] >= doc["steps"][2]["start_s"], broken  # not at the place, at the run
    assert "invariant 2 (danger_point)" in broken["seen"] and "train T1's head" in broken["seen"]


def test_lab_invariants_words_are_checked_before_anything_runs(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(FAILS_CLEAR.replace("lab invariants hold", "lab invariant holds"))
    with pytest.raises(ConfigError, match=r"always\[0\]: lab invariants hold \(the lab safety"):
        load_procedure(path)
    path.write_text(FAILS_CLEAR)
    procedure = load_procedure(path)
    assert procedure.checks_invariants
    stations = (18, 20, 22)
    read = {"tc", *(f"{kind}{n}" for kind in ("ixl", "io") for n in stations)}
    assert set(procedure.always[0].devices) == read  # the CTC's views and the ATCs: not read
