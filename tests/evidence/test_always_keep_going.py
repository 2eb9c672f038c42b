"""Procedures that say more: `always:` expectations hold at every sample alongside the steps (a
broken one fails the procedure, reported with when and what was seen), and `--keep-going` runs
the steps after a failed expectation, so what the lab did next is recorded. Real in-process
runs through `ktcs-bench test run`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from ktcs_bench.datafiles import data_dir

QUIET = data_dir("emulators") / "procedures" / "labs" / "quiet.yaml"
ALWAYS = f"""\
id: always
title: a route set at 18 while signal 01 must stay at stop, and 20's 21 does
verifies: [IXL-ROUTE-01]
setup: {{lab: '{QUIET}'}}
always:
  - ixl 18 signal 01 is R
  - ixl 20 signal 21 is R
steps:
  - ctc: route set 18 S1 S11
  - expect: ctc 18 signal 01 is Y,YG,G
    within: 15s
  - ctc: route cancel 18 S1 S11
  - expect: ctc 18 signal 01 is R
"""
GOING = f"""\
id: going
title: a failed expectation, then a route set
verifies: [IXL-ROUTE-01]
setup: {{lab: '{QUIET}'}}
steps:
  - expect: ctc 18 signal 01 is G
    within: 1s
  - ctc: route set 18 S1 S11
  - expect: ctc 18 signal 01 is not R
    within: 15s
  - ctc: route cancel 18 S1 S11
"""


def run(tmp_path: Path, text: str, *extra: str) -> tuple[int, dict[str, Any], str]:
    path = tmp_path / "p.yaml"
    path.write_text(text, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "test", "run", str(path),
         "--json", *extra],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    doc = json.loads(done.stdout)["procedures"][0] if done.stdout.strip() else {}
    return done.returncode, doc, done.stderr


def test_an_always_expectation_broken_fails_the_procedure_with_when_and_what(
    tmp_path: Path,
) -> None:
    code, doc, err = run(tmp_path, ALWAYS)
    assert code == 1, err
    assert [s["verdict"] for s in doc["steps"]] == ["pass"] * 4  # every step passed ...
    assert doc["verdict"] == "fail"  # ... but signal 01 cleared
    assert doc["always"] == ["ixl 18 signal 01 is R", "ixl 20 signal 21 is R"]
    [broken] = doc["broken"]  # 20's signal 21 held throughout
    assert broken["expectation"] == "ixl 18 signal 01 is R" and broken["seen"] in ("Y", "YG", "G")
    assert 0 < broken["t_s"] <= doc["steps"][1]["start_s"] + doc["steps"][1]["duration_s"]
    assert doc["message"].startswith("always: ixl 18 signal 01 is R broken at")


def test_keep_going_runs_the_steps_after_a_failed_expectation(tmp_path: Path) -> None:
    code, doc, err = run(tmp_path, GOING)
    assert code == 1, err
    assert [s["verdict"] for s in doc["steps"]] == ["fail", "skipped", "skipped", "skipped"]
    code, doc, err = run(tmp_path, GOING, "--keep-going")
    assert code == 1, err
    assert [s["verdict"] for s in doc["steps"]] == ["fail", "pass", "pass", "pass"]
    assert doc["verdict"] == "fail" and doc["message"].startswith("step 1 (expect: ctc 18 signal")


def test_always_of_an_event_is_refused_before_anything_runs(tmp_path: Path) -> None:
    text = ALWAYS.replace("  - ixl 20 signal 21 is R\n", '  - event ixl18 "route"\n')
    code, _doc, err = run(tmp_path, text)
    assert code == 2 and "always[1]: always: holds of a state, not of an event" in err, err


COMPARE = f"""\
id: compare
title: two placed trains compared live
verifies: [SYS-SAFE-02]
setup:
  lab: '{QUIET}'
  trains:
    - {{id: T1, head: 300, length_m: 40}}
    - {{id: T2, head: 900, length_m: 40}}
always:
  - train T1 head < train T2 tail - 200
steps:
  - expect: train T1 head < train T2 tail - 500
  - expect: train T1 head > train T2 tail
    within: 1s
"""


def test_an_expectation_compares_two_live_values(tmp_path: Path) -> None:
    code, doc, err = run(tmp_path, COMPARE)
    assert code == 1, err
    steps = doc["steps"]
    assert steps[0]["verdict"] == "pass" and steps[0]["seen"] == "300.0 (against 360)"
    assert steps[1]["verdict"] == "fail" and steps[1]["seen"] == "300.0 (against 860)"
    assert doc["broken"] == []  # 300 < 860 - 200 held throughout
    bad = COMPARE.replace("train T2 tail - 500", "train T2 tail - lots")
    code, _doc, err = run(tmp_path, bad)
    assert code == 2 and "- takes a number, not 'lots'" in err, err


COUNTED = f"""\
id: counted
title: of two signals at 18 at most one clears, at least one stays at stop
verifies: [IXL-INV-01]
setup: {{lab: '{QUIET}'}}
always:
  - at most 1 of ixl 18 signal 01, ixl 18 signal 02 is not R
  - at least 1 of ixl 18 signal 01, ixl 18 signal 02 is R
steps:
  - ctc: route set 18 S1 S11
  - expect: at least 1 of ixl 18 signal 01, ixl 18 signal 02 is Y,YG,G
    within: 15s
  - expect: at most 0 of ixl 18 signal 01, ixl 18 signal 02 is not R
    within: 1s
"""


def test_at_most_and_at_least_count_the_values_that_hold(tmp_path: Path) -> None:
    code, doc, err = run(tmp_path, COUNTED)
    assert code == 1, err
    assert doc["broken"] == []  # one cleared, the other stayed at stop: both always held
    steps = doc["steps"]
    assert [s["verdict"] for s in steps] == ["pass", "pass", "fail"]
    assert steps[2]["seen"].startswith("1 of 2 (")
    bad = COUNTED.replace("at most 0 of", "at most none of")
    code, _doc, err = run(tmp_path, bad)
    assert code == 2 and "at most N of VALUE" in err, err
