"""A procedure file is checked whole before anything runs: each mistake is one message naming the
file, the step and what is wrong (exit 2), and every shipped procedure reads clean."""

from __future__ import annotations

from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.procedure.steps import CtcStep, ExpectStep, FaultStep, TrainStep, WaitStep

HEAD = "id: p\ntitle: t\nsetup: {lab: reference}\nsteps:\n"
SHIPPED = sorted((data_dir("emulators") / "procedures").glob("*.yaml"))


def write(tmp_path: Path, steps: str, head: str = HEAD) -> Path:
    path = tmp_path / "p.yaml"
    path.write_text(head + steps, encoding="utf-8")
    return path


BAD = [
    # (steps, the place named, words of the problem)
    ("  - ctc: route set 99 01 11\n", "step 1 (ctc)", "no station 99"),
    ("  - ctc: route sideways 18 01 11\n", "step 1 (ctc)", "cannot read"),
    ("  - wait: 5s\n  - expect: ctc 18 signal 07 is R\n", "step 2 (expect)", "no signal '07'"),
    ("  - expect: ctc 18 signal 01 R\n", "step 1 (expect)", "expected is, is not"),
    ("  - expect: code TC9999 is stop\n", "step 1 (expect)", "no track circuit 'TC9999'"),
    ("  - expect: code TC1851 speed > fast\n", "step 1 (expect)", "takes a number"),
    ("  - expect: ctc 18 signal 01 is R\n    within: soon\n", "step 1 (expect)", "a duration is a positive number"),
    ("  - expect: ctc 18 signal 01 is R\n    within: 5s\n    holds: 5s\n", "step 1 (expect)",
     "not both"),
    ("  - wait: -3s\n", "step 1 (wait)", "a duration is a positive number"),
    ("  - fault: link st99-atc cut\n", "step 1 (fault)", "no link 'st99-atc'"),
    ("  - fault: link st18-atc ber lots\n", "step 1 (fault)", "not a number"),
    ("  - fault: point 18 31 melted\n", "step 1 (fault)", "detection, jammed"),
    ("  - fault: kill ixl99\n", "step 1 (fault)", "no device 'ixl99'"),
    ("  - train: T7 run to 300\n", "step 1 (train)", "no train 'T7'"),
    ("  - train: 1001 run to 5200 at 30\n", "step 1 (train)", "without at KMH"),
    ("  - train: 1001 dispatch later\n", "step 1 (train)",
     "hold, dispatch [now], run to AT, release_eb, not 'dispatch later'"),
    ("  - expect: frame st18-atc ctc>atc18 op NAK\n", "step 1 (expect)", "goes ixl18>atc18"),
    ("  - expect: ctc 18 signal 01 is R\n    wihtin: 5s\n", "step 1 (expect)",
     "unknown key 'wihtin'"),
    ("  - ctc: route set 18 01 11\n    expect: ctc 18 route 0111 is set\n", "step 1 (ctc)",
     "this one has several (ctc, expect)"),
    ("  - shout: hello\n", "step 1", "has none"),
    ("  - just words\n", "step 1", "a step is a mapping"),
]  # fmt: skip


@pytest.mark.parametrize(("steps", "place", "problem"), BAD)
def test_a_bad_step_is_one_message_naming_file_step_and_problem(
    tmp_path: Path, steps: str, place: str, problem: str
) -> None:
    path = write(tmp_path, steps)
    with pytest.raises(ConfigError) as err:
        load_procedure(path)
    assert err.value.file == str(path)
    assert err.value.place == place
    assert problem in err.value.problem
    assert str(err.value).startswith(f"{path}: {place}: ")


@pytest.mark.parametrize(
    ("head", "place", "problem"),
    [
        ("id: p\nsetup: {lab: nowhere}\nsteps:\n", "setup.lab", "no such lab"),
        ("id: p\nsetup: {modes: {18: remote}}\nsteps:\n", "setup.modes.18", "center or local"),
        ("id: p\nsetup: {modes: {17: local}}\nsteps:\n", "setup.modes.17", "no station 17"),
        ("id: p\nsetup: {trains: [{id: T1, head: TC0000}]}\nsteps:\n", "setup.trains[0].head",
         "no track circuit"),
        ("id: p\nstpes: []\nsteps:\n", "stpes", "unknown key"),
    ],
)  # fmt: skip
def test_a_bad_setup_names_its_key(tmp_path: Path, head: str, place: str, problem: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_procedure(write(tmp_path, "  - wait: 1s\n", head))
    assert err.value.place == place
    assert problem in err.value.problem


def test_a_procedure_without_steps_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="at least one step"):
        load_procedure(write(tmp_path, "", "id: p\nsteps: []\n"))


def test_test_run_refuses_a_bad_file_with_exit_2_before_running_anything(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = SHIPPED[0]
    bad = write(tmp_path, "  - expect: ctc 18 signal 07 is R\n")
    assert main(["test", "run", "--live", "no-such-lab", str(good), str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: step 1 (expect): station 18 has no signal '07'" in err
    assert err.count("\n") == 1  # one message, no traceback


def test_test_run_says_the_lab_is_unreachable_with_exit_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("KTCS_BENCH_RUN_DIR", str(tmp_path / "run"))
    assert main(["test", "run", "--live", "no-such-lab", str(SHIPPED[0])]) == 3
    assert "lab no-such-lab is not running" in capsys.readouterr().err


def test_the_shipped_suite_reads_clean_and_covers_the_issue() -> None:
    procedures = [load_procedure(p) for p in SHIPPED]
    assert len(procedures) >= 10
    assert len({p.id for p in procedures}) == len(procedures)
    kinds = {type(s) for p in procedures for s in p.steps}
    assert {CtcStep, ExpectStep, FaultStep, TrainStep, WaitStep} <= kinds
    assert all(p.verifies and p.title and p.tags for p in procedures)


@pytest.mark.parametrize(
    ("head", "place", "problem"),
    [
        ("id: p\nsetup:\n  lab: reference\n  arss: true\nsteps:\n", "setup.arss", "unknown key"),
        ("id: p\nsetup:\n  ars: 5\nsteps:\n", "setup.ars", "expected true or false, got a number 5"),
        ("id: p\nsetup:\n  trains: [{id: T1, head: TC1851, length_m: 0.5}]\nsteps:\n",
         "setup.trains[0].length_m", "must be at least 1, got 0.5"),
        ("id: p\nsetup:\n  trains: [{id: T1, head: TC1851, lenght_m: 40}]\nsteps:\n",
         "setup.trains[0].lenght_m", "unknown key"),
        ("id: p\ntags: {a: 1}\nsteps:\n", "tags", "expected text, got a mapping"),
    ],
    ids=["setup-key", "ars", "length", "train-key", "tags"],
)  # fmt: skip
def test_the_top_level_and_setup_are_declared_each_mistake_with_its_line(
    tmp_path: Path, head: str, place: str, problem: str
) -> None:
    path = write(tmp_path, "  - wait: 1s\n", head)
    with pytest.raises(ConfigError) as err:
        load_procedure(path)
    assert err.value.place == place, str(err.value)
    assert err.value.problem.startswith(problem), str(err.value)
    assert err.value.problem.endswith(")") and "(line " in err.value.problem, str(err.value)


def test_one_text_or_a_list_of_them_and_the_file_name_by_default(tmp_path: Path) -> None:
    path = write(tmp_path, "  - wait: 1s\n", "verifies: IXL-ROUTE-01\ntags: [a, 2]\nsteps:\n")
    procedure = load_procedure(path)
    assert (procedure.id, procedure.title) == ("p", "p")
    assert procedure.verifies == ("IXL-ROUTE-01",) and procedure.tags == ("a", "2")
