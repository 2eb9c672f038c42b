"""`ktcs-bench COMMAND` builds the parser of COMMAND alone: a lab starts dozens of `ktcs-bench
emulator` processes, and each imported every other command's modules (charts, decode, threats...)
before it ran, in start-up time and in memory."""

from __future__ import annotations

import subprocess
import sys

from .conftest import cli

LOADED = (
    "import sys\n"
    "from ktcs_bench.cli.main import build_parser\n"
    "build_parser({!r})\n"
    "print(' '.join(sorted(m for m in sys.modules if m.startswith('ktcs_bench.cli.'))))\n"
)


def _cli_modules(command: str | None) -> list[str]:
    run = subprocess.run([sys.executable, "-c", LOADED.format(command)],
                         capture_output=True, text=True, timeout=60, check=True)  # fmt: skip
    return run.stdout.split()


def test_a_command_imports_its_own_module_alone() -> None:
    assert _cli_modules("emulator") == [
        "ktcs_bench.cli._common",
        "ktcs_bench.cli.emulator",
        "ktcs_bench.cli.main",
    ]
    assert "ktcs_bench.cli.decode" in _cli_modules(None)  # no command: all of them


def test_an_unknown_command_is_refused_naming_every_command() -> None:
    result = cli("--no-colour", "emulater")
    assert result.returncode == 2
    for command in ("emulator", "decode", "lab", "threats"):
        assert command in result.stderr, result.stderr


def test_options_before_the_command_still_apply() -> None:
    result = cli("--no-colour", "emulator", "--help")
    assert result.returncode == 0
    assert "--link PEER=ENDPOINT" in result.stdout
