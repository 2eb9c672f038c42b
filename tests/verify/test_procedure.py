"""A counterexample written as a procedure replays in the lab: run by `test run` on the quiet lab
in this process (virtual time), it fails with the core's check switched off -- the lab shows the
same violation -- and passes with the core as shipped."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.ixl import Interlocking
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.verify.explore import Bound, explore_station
from ktcs_bench.verify.procedure import write_procedure
from tests.verify.seeds import reference


def _run(path: Path, report: Path) -> str:
    assert main(["test", "run", str(path), "--report", str(report), "--no-colour"]) in (0, 1)
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    [verdict] = [p["verdict"] for p in results["procedures"]]
    return str(verdict)


def test_the_written_procedure_replays_the_violation_in_the_lab(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(Interlocking, "occupancy_check_disabled_for_tests", True)
    bound = Bound(requests=1, faults=1)
    [violation] = explore_station(reference(), 18, bound).violations
    path = write_procedure(reference(), bound, violation, tmp_path / "procs", 1)
    procedure = load_procedure(path)
    assert procedure.verifies == ("IXL-INV-03", "IXL-INV-04")
    steps = [s.text for s in procedure.steps]
    assert steps == ["route set 18 01 11", "tc TC1855 failed_occupied", "2s",
                     "ixl 18 signal 01 is R"]  # fmt: skip
    assert _run(path, tmp_path / "defective") == "fail"
    monkeypatch.setattr(Interlocking, "occupancy_check_disabled_for_tests", False)
    assert _run(path, tmp_path / "sound") == "pass"
    capsys.readouterr()
