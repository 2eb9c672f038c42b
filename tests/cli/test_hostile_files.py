"""What a careless or hostile user gives as a data file (issue 21 items 4, 5, 9): a YAML bomb, a
binary file, an empty one, a nesting or a number no file means, a wait of 10000 h. Each is one
short message naming the file (and the line) and exit 2 -- never a traceback, a hang, or memory
sized by the file's aliases. Every test runs the real `ktcs-bench` command under a memory limit."""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from ktcs_bench.datafiles import MAX_ALIAS_NODES, MAX_DEPTH, data_dir, load_yaml, yaml_loader
from ktcs_bench.errors import ConfigError
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.scenario.model import load_scenario

from .conftest import CLI, shipped_lab

EXIT_USAGE = 2
MEMORY = 1 << 30  # what the command may map: the bombs below need gigabytes once written out
SHORT = 2000  # bytes of stderr: a message, not the file's values
HEAD = "id: p\ntitle: t\nsetup: {lab: reference}\nsteps:\n"
SCENARIO = """\
name: s
duration_s: 60
stop_when_all_stopped: true
line: {length_m: 1150, tags: {spacing_m: 50}}
trains:
  - {id: T1, start_m: 20, length_m: 20, max_speed_kmh: 40}
"""


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """The command with at most MEMORY of address space and two minutes."""
    return subprocess.run(
        [*CLI, *args], capture_output=True, text=True, timeout=120, preexec_fn=_limit_memory,
        env={**os.environ, **(env or {})}, stdin=subprocess.DEVNULL,
    )  # fmt: skip


def assert_refused(result: subprocess.CompletedProcess[str], *needles: str) -> None:
    """Exit 2, one short line on stderr holding every needle, no traceback."""
    assert result.returncode == EXIT_USAGE, (result.returncode, result.stderr[:SHORT])
    assert len(result.stderr.encode()) < SHORT, result.stderr[:SHORT]
    assert "Traceback" not in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    for needle in needles:
        assert needle in result.stderr, (needle, result.stderr)


def nested_anchors(levels: int = 9) -> str:
    """A flow list of anchors each holding nine aliases of the one before: 9**levels values once
    written out (9 levels: 387 million, 2.5 GB as Python's str of it)."""
    items = [f"&a0 [{', '.join(['lol'] * 9)}]"]
    items += [f"&a{n} [{', '.join([f'*a{n - 1}'] * 9)}]" for n in range(1, levels)]
    return "[" + ",\n  ".join(items) + "]"


# -- item 4: a YAML bomb is refused while it is still small -----------------------------------


@pytest.mark.parametrize(
    ("text", "line"),
    [
        (f"id: bomb\ntitle: {nested_anchors()}\nsteps:\n  - wait: 1s\n", 6),
        (f"id: bomb\nsteps:\n  - wait: 1s\n    note: {nested_anchors()}\n", 8),
    ],
    ids=["title", "note"],
)
def test_a_yaml_bomb_in_a_procedure_is_refused_at_load_naming_file_and_line(
    tmp_path: Path, text: str, line: int
) -> None:
    """Aliases share one node while the file is parsed; a text check (or its message quoting the
    value) wrote them out -- 2.5 GB and a hang, or a 351 MB message. The line is the anchor's
    whose aliases take the count past the bound."""
    path = tmp_path / "bomb.yaml"
    path.write_text(text, encoding="utf-8")
    result = run("test", "run", str(path))
    assert_refused(result, f"{path}: line {line}, column 3: aliases repeat more than ")


@pytest.mark.parametrize("fast", [True, False], ids=["libyaml", "pure-python"])
@pytest.mark.parametrize(
    ("text", "problem"),
    [
        (f"a: {nested_anchors()}\n", f"more than {MAX_ALIAS_NODES} values"),
        ("a: &a [1, *a]\n", "an alias inside its own anchor"),
        ("a: " + "[" * 300 + "]" * 300 + "\n", f"nested deeper than {MAX_DEPTH} levels"),
    ],
    ids=["bomb", "self-alias", "deep"],
)
def test_both_parsers_refuse_a_document_alike_before_it_is_constructed(
    fast: bool, text: str, problem: str
) -> None:
    """libyaml composes in C, the fallback in Python (recursively: at some hundreds of levels a
    RecursionError): the check runs on the composed nodes of either, with the same words."""
    with pytest.raises(Exception, match=problem):
        yaml.load(text, Loader=yaml_loader(fast))  # noqa: S506 -- a safe loader


def test_anchors_and_merge_keys_used_as_meant_still_load(tmp_path: Path) -> None:
    """Settings given once and merged into each train: what anchors are for."""
    path = tmp_path / "scenario.yaml"
    path.write_text(
        SCENARIO.replace(
            "  - {id: T1, start_m: 20, length_m: 20, max_speed_kmh: 40}\n",
            "  - &train {id: T1, start_m: 20, length_m: 20, max_speed_kmh: 40}\n"
            "  - {<<: *train, id: T2, start_m: 600}\n",
        ),
        encoding="utf-8",
    )
    scenario = load_scenario(path)
    t1, t2 = scenario.trains
    assert (t1.train_id, t2.train_id, t1.start, t2.start) == ("T1", "T2", 20.0, 600.0)
    assert t2.params == t1.params
    assert load_yaml(path) == yaml.safe_load(path.read_text(encoding="utf-8"))


def test_a_long_value_is_quoted_as_a_short_excerpt(tmp_path: Path) -> None:
    """No alias, just a long list where text belongs: the message quotes its start."""
    path = tmp_path / "long.yaml"
    path.write_text(f"title: [{', '.join(['lol'] * 200_000)}]\nsteps: [wait: 1s]\n")
    result = run("test", "run", str(path))
    assert_refused(result, f"{path}: title: expected text, got a list ['lol', 'lol', ")


# -- item 5: a file that is not YAML text, or not a mapping -----------------------------------


def _procedure(tmp: Path, bad: Path) -> list[str]:
    return ["test", "run", str(bad)]


def _lab_simulate(tmp: Path, bad: Path) -> list[str]:
    return ["lab", "simulate", str(bad), "--for", "1", "--out", str(tmp / "out")]


def _lab_up(tmp: Path, bad: Path) -> list[str]:
    return ["lab", "up", str(bad), "--for", "1"]


def _scenario(tmp: Path, bad: Path) -> list[str]:
    return ["scenario", "run", str(bad), "--out", str(tmp / "out")]


def _line(tmp: Path, bad: Path) -> list[str]:
    return ["chart", "generate", "--line", str(bad), "--out", str(tmp / "charts")]


def _station(tmp: Path, bad: Path) -> list[str]:
    """A line whose station 18 is the bad file."""
    stations = (data_dir("emulators") / "stations").resolve()
    text = (data_dir("emulators") / "lines" / "reference.yaml").read_text(encoding="utf-8")
    text = text.replace("../stations/st18.yaml", str(bad)).replace("../stations/", f"{stations}/")
    line = tmp / "line.yaml"
    line.write_text(text, encoding="utf-8")
    return _line(tmp, line)


def _timetable(tmp: Path, bad: Path) -> list[str]:
    """The reference lab with the bad file as its timetable."""
    timetable = (data_dir("emulators") / "timetables" / "reference.yaml").resolve()
    lab = shipped_lab(tmp, {f"timetable: {timetable}": f"timetable: {bad}"})
    return _lab_simulate(tmp, lab)


KINDS = [_procedure, _lab_simulate, _lab_up, _scenario, _line, _station, _timetable]
KIND_IDS = ["procedure", "lab-simulate", "lab-up", "scenario", "line", "station", "timetable"]


@pytest.mark.parametrize("command", KINDS, ids=KIND_IDS)
def test_a_binary_file_given_as_yaml_is_one_line_not_utf8_and_exit_2(
    tmp_path: Path, run_env: dict[str, str], command: object
) -> None:
    assert callable(command)
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"id: x\n\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    result = run(*command(tmp_path, bad), env=run_env)
    assert_refused(result, f"{bad}: line 2: not UTF-8 text")


def test_a_file_of_control_characters_is_one_line_not_yaml_text(tmp_path: Path) -> None:
    """Valid UTF-8 yet binary (NUL bytes): PyYAML's reader error ran over two lines."""
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"id: x\ntitle: \x00\x01\x02\n")
    assert_refused(run("test", "run", str(bad)), f"{bad}: line 2: not YAML text: character #x0000")


def test_an_endless_file_given_as_yaml_is_refused_after_a_bounded_read(tmp_path: Path) -> None:
    """/dev/zero never ends: the whole of it was read into memory."""
    assert_refused(run("test", "run", "/dev/zero"), "/dev/zero: larger than 16 MB")


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("", "empty: a {} file is a YAML mapping (key: value lines)"),
        ("# nothing but a comment\n", "empty: a {} file is a YAML mapping"),
        ("- id: p\n- steps: []\n", "a {} file is a YAML mapping (key: value lines), not a list"),
        ("hello\n", "a {} file is a YAML mapping (key: value lines), not text"),
    ],
    ids=["empty", "comment", "list", "text"],
)
@pytest.mark.parametrize("command", KINDS, ids=KIND_IDS)
def test_an_empty_file_or_one_whose_top_is_not_a_mapping_says_so(
    tmp_path: Path, run_env: dict[str, str], command: object, text: str, problem: str
) -> None:
    assert callable(command)
    what = {
        _procedure: "procedure", _lab_simulate: "lab", _lab_up: "lab", _scenario: "scenario",
        _line: "line", _station: "station", _timetable: "timetable",
    }[command]  # fmt: skip
    bad = tmp_path / "bad.yaml"
    bad.write_text(text, encoding="utf-8")
    result = run(*command(tmp_path, bad), env=run_env)
    assert_refused(result, f"{bad}: {problem.format(what)}")


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (
            "a: " + "[" * 2000 + "]" * 2000 + "\n",
            f"line 1, column 103: nested deeper than {MAX_DEPTH}",
        ),
        ("id: " + "7" * 5000 + "\n", "line 1, column 5: invalid YAML: a number of 5000 digits"),
    ],
    ids=["deeper-than-libyaml", "huge-number"],
)
def test_a_nesting_or_number_no_file_means_is_refused(
    tmp_path: Path, text: str, needle: str
) -> None:
    """libyaml stops at 1000 levels, and the pure-Python parser then recursed past Python's limit;
    int() refused 4300+ digits: both were tracebacks."""
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    assert_refused(run("test", "run", str(path)), f"{path}: {needle}")


# -- item 9: durations nothing can wait out ---------------------------------------------------


@pytest.mark.parametrize(
    ("steps", "place", "value"),
    [
        ("  - expect: ctc 18 signal 01 is R\n    within: 10000h\n", "step 1 (expect)", "'10000h'"),
        ("  - expect: ctc 18 signal 01 is R\n    holds: 25h\n", "step 1 (expect)", "'25h'"),
        ("  - wait: 86401\n", "step 1 (wait)", "86401"),
        (
            "  - wait until: ctc 18 signal 01 is R\n    within: 2000min\n",
            "step 1 (wait until)",
            "'2000min'",
        ),
    ],
    ids=["within", "holds", "wait", "wait-until"],
)
def test_a_procedure_duration_beyond_24_h_is_refused_naming_the_bound(
    tmp_path: Path, steps: str, place: str, value: str
) -> None:
    """`within: 10000h` was taken, and a virtual run spun on for hours."""
    path = tmp_path / "p.yaml"
    path.write_text(HEAD + steps, encoding="utf-8")
    assert_refused(
        run("test", "run", str(path)),
        f"{path}: {place}: a duration here is at most 24 h (86400 s), not {value}",
    )


def test_a_procedure_whose_waits_add_up_beyond_24_h_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(HEAD + "  - wait: 13h\n  - expect: ctc 18 signal 01 is R\n    holds: 12h\n")
    assert_refused(
        run("test", "run", str(path)),
        f"{path}: steps: the waits, within: and holds: add up to 25 h (90000 s); a procedure "
        "takes at most 24 h (86400 s) of lab time",
    )


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        ({"duration_s: 60": "duration_s: 36000000"}, "duration_s: must be at most 86400"),
        ({"duration_s: 60": "duration_s: 3600\ndt_s: 0.001"}, "dt_s: 1 h (3600 s) in steps of"),
        ({"length_m: 1150": "length_m: 1.0e+12"}, "line.length_m: must be at most 1e+06"),
        (
            {"max_speed_kmh: 40}": "max_speed_kmh: 40, missed_tags: [abc]}"},
            "trains[0].missed_tags[0]: expected a number, got text 'abc'",
        ),
    ],
    ids=["duration", "cycles", "length", "missed-tags"],
)
def test_a_scenario_that_cannot_run_is_refused_naming_the_bound(
    tmp_path: Path, edit: dict[str, str], needle: str
) -> None:
    """24 h of virtual time at most, 500000 cycles, a line of 1000 km: a scenario keeps every
    cycle of every train, and lays its tags out one by one."""
    text = SCENARIO
    for old, new in edit.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "scenario.yaml"
    path.write_text(text, encoding="utf-8")
    result = run("scenario", "run", str(path), "--out", str(tmp_path / "out"))
    assert_refused(result, f"{path}: {needle}")
    assert not (tmp_path / "out").exists()


def test_the_shipped_data_files_load_within_the_bounds(tmp_path: Path) -> None:
    """Every shipped YAML file (and the procedures' and scenarios' durations) is inside the
    bounds: the checks refuse only what no shipped file does."""
    for folder in ("emulators", "protocols", "code_charts"):
        for path in sorted(data_dir(folder).rglob("*.yaml")):
            try:
                load_yaml(path)
            except ConfigError as exc:  # pragma: no cover - the failure message
                pytest.fail(str(exc))
    for path in sorted((data_dir("emulators") / "procedures").glob("*.yaml")):
        load_procedure(path)
    for path in sorted((data_dir("emulators") / "scenarios").glob("*.yaml")):
        shutil.copy(path, tmp_path / path.name)
        load_scenario(tmp_path / path.name)
