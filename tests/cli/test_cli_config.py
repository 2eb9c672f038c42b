"""Configuration a user writes -- YAML files, ports, durations -- is checked before anything runs:
a clear message naming what is wrong and exit 2, never a traceback and never a silently other
meaning (issue 13 item 7). Every test runs the real `ktcs-bench` command."""

from __future__ import annotations

import argparse
import re
import shutil
from pathlib import Path

import pytest

from ktcs_bench.argtypes import seconds
from ktcs_bench.cli._common import duration
from ktcs_bench.cli.main import build_parser
from ktcs_bench.datafiles import data_dir, load_yaml, yaml_parser_in_c
from ktcs_bench.errors import ConfigError

from .conftest import cli, shipped_lab

EXIT_USAGE = 2
FIG7 = str(data_dir("protocols") / "captures" / "fig7.hex")


def assert_refused(result: object, *needles: str) -> None:
    """Exit 2, every needle in stderr, no traceback."""
    assert hasattr(result, "returncode") and hasattr(result, "stderr")
    assert result.returncode == EXIT_USAGE, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    for needle in needles:
        assert needle in result.stderr, (needle, result.stderr)


def duplicate_line(path: Path, line: str) -> int:
    """Write `line` (present once in `path`) a second time right under itself; return the
    1-based number of the copy."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    at = [i for i, ln in enumerate(lines) if ln.rstrip("\n") == line]
    assert len(at) == 1, (line, at)
    lines.insert(at[0] + 1, lines[at[0]])
    path.write_text("".join(lines), encoding="utf-8")
    return at[0] + 2


# -- every YAML file refuses a key given twice ----------------------------------------------------


@pytest.mark.parametrize(
    ("key", "line"),
    [
        ("tc", "  tc:     {kind: trackcircuit, host: 127.0.0.1}"),
        ("ixl18", "  ixl18:  {kind: ixl, station: 18, host: 127.0.0.1}"),
        ("console", "console:"),
    ],
)
def test_lab_file_with_a_key_given_twice_is_refused_naming_file_line_and_key(
    tmp_path: Path, run_env: dict[str, str], key: str, line: str
) -> None:
    lab = shipped_lab(tmp_path, {})
    copy = duplicate_line(lab, line)
    result = cli("lab", "up", str(lab), "--for", "5", env=run_env)
    assert_refused(result, f"{lab}: line {copy}", f"duplicate key {key!r}", f"line {copy - 1}")
    assert not (tmp_path / "run" / "labs").exists()  # nothing was started


def _profile(tmp: Path) -> tuple[Path, list[str]]:
    path = tmp / "type1.yaml"
    shutil.copy(data_dir("protocols") / "type1.yaml", path)
    return path, ["decode", "--profile", f"{path}:ktcs-type1", "02 00 00 01 00"]


def _chart(tmp: Path) -> tuple[Path, list[str]]:
    path = tmp / "chart.yaml"
    shutil.copy(data_dir("code_charts") / "st18_ixl_to_ctc.yaml", path)
    return path, ["decode", "--chart", str(path), FIG7]


def _scenario(tmp: Path) -> tuple[Path, list[str]]:
    path = tmp / "scenario.yaml"
    shutil.copy(data_dir("emulators") / "scenarios" / "seed001_follower.yaml", path)
    return path, ["scenario", "run", str(path), "--out", str(tmp / "report")]


def _line(tmp: Path) -> tuple[Path, list[str]]:
    stations = (data_dir("emulators") / "stations").resolve()
    path = tmp / "line.yaml"
    text = (data_dir("emulators") / "lines" / "reference.yaml").read_text(encoding="utf-8")
    path.write_text(text.replace("../stations/", f"{stations}/"), encoding="utf-8")
    return path, ["chart", "generate", "--line", str(path), "--out", str(tmp / "charts")]


def _station(tmp: Path) -> tuple[Path, list[str]]:
    line, args = _line(tmp)
    path = tmp / "st18.yaml"
    shutil.copy(data_dir("emulators") / "stations" / "st18.yaml", path)
    stations = str((data_dir("emulators") / "stations").resolve())
    line.write_text(
        line.read_text(encoding="utf-8").replace(f"{stations}/st18.yaml", str(path)),
        encoding="utf-8",
    )
    return path, args


@pytest.mark.parametrize(
    ("make", "key", "line"),
    [
        (_profile, "poly", "    poly: 0x18005"),
        (_chart, "station", "station: 18"),
        (_scenario, "duration_s", "duration_s: 900"),
        (_line, "end_m", "end_m: 13300"),
        (_station, "tracks", 'tracks: ["1", "2"]'),
    ],
    ids=["profile", "chart", "scenario", "line", "station"],
)
def test_every_kind_of_yaml_file_refuses_a_key_given_twice(
    tmp_path: Path, make: object, key: str, line: str
) -> None:
    assert callable(make)
    path, args = make(tmp_path)
    copy = duplicate_line(path, line)
    result = cli(*args)
    assert_refused(result, f"{path}: line {copy}", f"duplicate key {key!r}")


def test_yaml_is_parsed_by_libyaml() -> None:
    """Every device process loads its line; the pure-Python parser made that ten times slower."""
    import yaml

    assert yaml.__with_libyaml__, "PyYAML was built without libyaml (its C parser is missing)"
    assert yaml_parser_in_c(), "load_yaml fell back to PyYAML's pure-Python parser"


@pytest.mark.parametrize(
    ("text", "place", "problem"),
    [
        ("a: [1, 2\n", "line 2, column 1", "expected ',' or ']', but got '<stream end>'"),
        ("a:\n\tb: 1\n", "line 2, column 1", "found character '\\t' that cannot start any token"),
        ("- a\nb: 1\n", "line 2, column 1", "expected <block end>, but found '?'"),
    ],
)
def test_yaml_syntax_error_reads_the_same_as_without_libyaml(
    tmp_path: Path, text: str, place: str, problem: str
) -> None:
    """libyaml words its errors otherwise ('did not find expected ...'); the message stays the
    one the pure-Python parser gives, at its line and column."""
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        load_yaml(path)
    assert str(caught.value) == f"{path}: {place}: invalid YAML: {problem}"


# -- ports: 1..65535, 0 only where any free port is meant -----------------------------------------


TC = "  tc:     {kind: trackcircuit, host: 127.0.0.1"


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("  port: 8020 ", "  port: 99999 ", "console.port: port 99999 is out of range 0..65535"),
        ("  port: 0    ", "  port: -1 ", "type2.port: port -1 is out of range 0..65535"),
        ("  port: 0    ", "  port: http ", "type2.port: the port must be a number 0..65535"),
        (TC, f"{TC}, port: 70000", "devices.tc.port: port 70000 is out of range 0..65535"),
    ],
    ids=["console", "type2-negative", "type2-word", "device"],
)
def test_lab_file_port_out_of_range_is_refused_naming_the_key(
    tmp_path: Path, run_env: dict[str, str], old: str, new: str, message: str
) -> None:
    lab = shipped_lab(tmp_path, {old: new})
    result = cli("lab", "up", str(lab), "--for", "5", env=run_env)
    assert_refused(result, f"{lab}: {message}")
    assert not (tmp_path / "run" / "labs").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["replay", FIG7, "--to", "tcp://127.0.0.1:99999"],
         "endpoint tcp://127.0.0.1:99999: port 99999 is out of range 1..65535"),
        (["monitor", "tcp://127.0.0.1:65536"],
         "endpoint tcp://127.0.0.1:65536: port 65536 is out of range 1..65535"),
        (["conformance", "--role", "ctc", "--target", "tcp://127.0.0.1:0"],
         "endpoint tcp://127.0.0.1:0: port 0 is out of range 1..65535"),
        (["conformance", "--role", "ixl", "--target", "listen://127.0.0.1:70000"],
         "port 70000 is out of range 0..65535 (0: any free port)"),
        (["emulator", "ixl", "--station", "18", "--link", "ctc=tcp://127.0.0.1:99999"],
         "endpoint tcp://127.0.0.1:99999: port 99999 is out of range 1..65535"),
        (["emulator", "ctc", "--listen", "127.0.0.1:99999"],
         "argument --listen: port 99999 is out of range 0..65535 (0: any free port)"),
        (["emulator", "trackcircuit", "--control", "127.0.0.1:-5"],
         "argument --control: port -5 is out of range 0..65535"),
        (["emulator", "ctc", "--console", "127.0.0.1:x"],
         "argument --console: the port must be a number 0..65535"),
        (["ctc", "--address", "127.0.0.1:99999", "show", "18"],
         "argument --address: port 99999 is out of range 1..65535"),
        (["ctc", "--address", "127.0.0.1:0", "show", "18"],
         "argument --address: port 0 is out of range 1..65535"),
        (["tap", "fault", "99999", "ber", "0"],
         "tap address 99999: port 99999 is out of range 1..65535"),
        (["tap", "run", "--tcp", "127.0.0.1:0", "127.0.0.1:99999"],
         "TARGET 127.0.0.1:99999: port 99999 is out of range 1..65535"),
        (["tap", "run", "--pty", "--control", "127.0.0.1:99999"],
         "--control 127.0.0.1:99999: port 99999 is out of range 0..65535"),
        (["threats", "--target", "127.0.0.1:99999"],
         "port 99999 is out of range 1..65535"),
        (["console", "--port", "99999"],
         "argument --port: port 99999 is out of range 0..65535 (0: any free port)"),
        (["console", "--ctc-port", "-1"],
         "argument --ctc-port: port -1 is out of range 0..65535"),
    ],
    ids=lambda v: " ".join(v[:2]) if isinstance(v, list) else "",
)  # fmt: skip
def test_a_port_out_of_range_is_a_usage_error_wherever_a_port_is_read(
    run_env: dict[str, str], args: list[str], message: str
) -> None:
    assert_refused(cli(*args, env=run_env, timeout=30), message)


def test_connect_to_port_99999_does_not_reach_its_value_modulo_65536(
    run_env: dict[str, str],
) -> None:
    """The socket layer would wrap 99999 to 34463 and connect there: a listener on 34463 must
    see nobody (it is asked after the command ended, so a connection would be queued)."""
    import socket

    with socket.socket() as listener:
        try:
            listener.bind(("127.0.0.1", 99999 - 65536))
        except OSError:
            pytest.skip("port 34463 is taken on this machine")
        listener.listen(1)
        listener.settimeout(0.5)
        result = cli("replay", FIG7, "--to", "tcp://127.0.0.1:99999", "--wait", "0.1", env=run_env)
        assert_refused(result, "port 99999 is out of range 1..65535")
        with pytest.raises(TimeoutError):
            listener.accept()[0].close()


# -- durations: one type, positive and finite -----------------------------------------------------

DURATION_OPTIONS = [
    ["lab", "up", "--for"],
    ["lab", "up", "--interval"],
    ["monitor", "x", "--timeout"],
    ["replay", "x", "--to", "loop://", "--wait"],
    ["console", "--throw-time"],
    *[["conformance", "--role", "atc", "--target", "loop://", opt] for opt in (
        "--delta-r", "--ack-timeout", "--heartbeat-period", "--link-test-period", "--t-max",
        "--tolerance")],
]  # fmt: skip


@pytest.mark.parametrize("option", DURATION_OPTIONS, ids=lambda o: f"{o[0]} {o[-1]}")
def test_a_negative_duration_is_refused_by_every_option_that_takes_one(
    run_env: dict[str, str], option: list[str]
) -> None:
    result = cli(*option, "-1", env=run_env, timeout=30)
    assert_refused(
        result,
        "argument --",
        option[-1],
        "a duration is a positive number of seconds (or 500ms, 5s, 2min, 1h), not '-1'",
    )


@pytest.mark.parametrize("value", ["0", "-0.5", "nan", "inf", "1e400", "soon", ""])
def test_delta_r_takes_only_a_positive_finite_number_of_seconds(
    run_env: dict[str, str], value: str
) -> None:
    result = cli(*DURATION_OPTIONS[5], value, env=run_env, timeout=30)
    assert DURATION_OPTIONS[5][-1] == "--delta-r"
    assert_refused(
        result,
        f"--delta-r: a duration is a positive number of seconds (or 500ms, 5s, 2min, 1h), not {value!r}",
    )


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    out: list[argparse.Action] = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in {id(p): p for p in action.choices.values()}.values():
                out += _options(child)
        else:
            out.append(action)
    return out


def test_every_option_that_takes_seconds_uses_the_one_duration_type() -> None:
    seconds = re.compile(r"\bseconds?\b|\(s\)|, s$")
    takes_seconds = [
        a for a in _options(build_parser())
        if a.option_strings and (a.metavar == "S" or seconds.search(a.help or ""))
    ]  # fmt: skip
    names = {a.option_strings[0] for a in takes_seconds}
    assert {"--for", "--interval", "--timeout", "--wait", "--throw-time", "--delta-r"} <= names
    assert [a.option_strings for a in takes_seconds if a.type is not duration] == []


# -- counts and rates: positive, whole where they count ----------------------------------------

COUNT_OPTIONS = [
    ["monitor", "x", "--count"],
    ["monitor", "x", "--baud"],
    ["replay", "x", "--to", "loop://", "--baud"],
    ["emulator", "atc", "--station"],
    *[["conformance", "--role", "atc", "--target", "loop://", opt] for opt in (
        "--line-rate", "--longest-frame", "--codes", "--station")],
]  # fmt: skip


@pytest.mark.parametrize("option", COUNT_OPTIONS, ids=lambda o: f"{o[0]} {o[-1]}")
@pytest.mark.parametrize("value", ["0", "-3"])
def test_a_count_or_rate_below_one_is_refused(
    run_env: dict[str, str], option: list[str], value: str
) -> None:
    result = cli(*option, value, env=run_env, timeout=30)
    assert_refused(result, "argument --", option[-1], f"≥ 1, not {value!r}")


def test_retry_count_may_be_zero_but_not_negative(run_env: dict[str, str]) -> None:
    base = ["conformance", "--role", "atc", "--target", "loop://", "--retry-count"]
    assert_refused(cli(*base, "-1", env=run_env, timeout=30), "--retry-count", "≥ 0, not '-1'")
    listed = cli(*base, "0", "--list", env=run_env, timeout=30)
    assert listed.returncode == 0, listed.stderr


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("console:\n", "console: 5\nx:\n", "console: must be a mapping of settings, not 5"),
        ("type1:\n", "type1: [a]\nx:\n", "type1: must be a mapping of settings, not ['a']"),
        ("  line_rate: 9600 ", "  line_rate: -9600 ", "type1.line_rate: must be a positive number"),
        ("  longest_frame_data: 132 ", "  longest_frame_data: 1.5 ",
         "type1.longest_frame_data: must be a positive whole number, not 1.5"),
    ],
    ids=["console-scalar", "type1-list", "line-rate", "longest-frame"],
)  # fmt: skip
def test_lab_file_sections_and_settings_of_the_wrong_shape_are_refused(
    tmp_path: Path, run_env: dict[str, str], old: str, new: str, message: str
) -> None:
    lab = shipped_lab(tmp_path, {old: new})
    result = cli("lab", "up", str(lab), "--for", "5", env=run_env)
    assert_refused(result, f"{lab}: {message}")


@pytest.mark.parametrize(
    ("text", "expected"),
    [("90", 90.0), ("1.5", 1.5), ("500ms", 0.5), ("5s", 5.0), ("2min", 120.0), ("15m", 900.0),
     ("1h", 3600.0), ("1e3", 1000.0), (7, 7.0)],
)  # fmt: skip
def test_a_duration_is_read_one_way_with_its_unit(text: object, expected: float) -> None:
    assert seconds(text) == expected
