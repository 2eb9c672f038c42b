"""One way to say colour, for every command (issue 13 item 9): `--colour/--no-colour` anywhere on
the command line, NO_COLOR honoured (https://no-color.org: set and not empty), and by default
colour only on a terminal. Real subprocesses; "a terminal" is a real pty."""

from __future__ import annotations

import argparse

import pytest

from ktcs_bench.cli.main import build_parser
from ktcs_bench.datafiles import data_dir

from .conftest import cli, cli_on_tty

ESC = "\x1b["
FIG7 = str(data_dir("protocols") / "captures" / "fig7.hex")  # monitor shows it with exit 0
GOOD = "0206000502000300010401001858000003"  # one good ktcs-type1 CHANGE frame: decode exits 0


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command path, `lab` and `lab up` alike."""
    out = [path]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                out += _commands(child, (*path, name))
    return out


COMMANDS = _commands(build_parser())


def test_the_command_list_is_complete() -> None:
    assert {("decode",), ("lab", "up"), ("ctc",), ("tap", "fault"), ("threats",)} <= set(COMMANDS)


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "ktcs-bench")
def test_every_command_takes_colour_and_no_colour(path: tuple[str, ...]) -> None:
    result = cli(*path, "--help")
    assert result.returncode == 0, result.stderr
    assert "--colour" in result.stdout and "--no-colour" in result.stdout, result.stdout


@pytest.mark.parametrize(
    ("args", "env", "coloured"),
    [
        ([], {}, True),  # a terminal, nothing said: colour
        ([], {"NO_COLOR": "1"}, False),
        ([], {"NO_COLOR": ""}, True),  # set but empty: not a request (no-color.org)
        (["--no-colour"], {}, False),
        (["--no-color"], {}, False),  # the other spelling
        (["--colour"], {"NO_COLOR": "1"}, True),  # the command line has the last word
        (["--no-colour", "--colour"], {}, True),  # the last one given wins
    ],
)
@pytest.mark.parametrize("command", [["decode", GOOD], ["monitor", FIG7]], ids=lambda c: c[0])
def test_colour_on_a_terminal(
    command: list[str], args: list[str], env: dict[str, str], coloured: bool
) -> None:
    code, out = cli_on_tty(*command, *args, env=env)
    assert code == 0, out
    assert "CRC OK" in out
    assert (ESC in out) is coloured, out


@pytest.mark.parametrize(
    ("args", "coloured"),
    [
        ([], False),  # a pipe: no colour
        (["--colour"], True),
        (["--color"], True),
        (["--colour", "--no-colour"], False),
    ],
)
def test_colour_into_a_pipe(args: list[str], coloured: bool) -> None:
    result = cli("decode", GOOD, *args, env={"NO_COLOR": ""})
    assert result.returncode == 0, result.stderr
    assert (ESC in result.stdout) is coloured, result.stdout


def test_colour_given_before_the_command_counts_for_it() -> None:
    assert ESC in cli("--colour", "decode", GOOD).stdout
    code, out = cli_on_tty("--no-colour", "monitor", FIG7, env={})
    assert code == 0 and "CRC OK" in out and ESC not in out, out
    # said again after the command, the later word wins
    assert ESC not in cli("--colour", "decode", GOOD, "--no-colour").stdout
