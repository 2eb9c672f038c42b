"""The `ktcs-bench` command as a user runs it: a real subprocess, its exit code and its words."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir

CLI = [sys.executable, "-m", "ktcs_bench.cli.main"]


def cli(
    *args: str, env: dict[str, str] | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*CLI, *args], capture_output=True, text=True, timeout=timeout,
        env={**os.environ, **(env or {})},
    )  # fmt: skip


def cli_on_tty(*args: str, env: dict[str, str], timeout: float = 120) -> tuple[int, str]:
    """The command with its stdout on a real terminal (a pty), as a person runs it: (exit code,
    what the terminal got). `env` replaces NO_COLOR handling of the caller's environment."""
    master, slave = os.openpty()
    base = {k: v for k, v in os.environ.items() if k != "NO_COLOR"}
    try:
        proc = subprocess.Popen(
            [*CLI, *args], stdout=slave, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
            env={**base, **env},
        )  # fmt: skip
        os.close(slave)
        slave = -1
        out = bytearray()
        deadline = time.monotonic() + timeout
        while True:
            if time.monotonic() > deadline:
                proc.kill()
                proc.wait()
                raise AssertionError(f"{args} did not end within {timeout} s")
            if not select.select([master], [], [], 0.2)[0]:
                continue
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            out += chunk
        proc.communicate(timeout=timeout)
        return proc.returncode, out.decode("utf-8", errors="replace")
    finally:
        if slave >= 0:
            os.close(slave)
        os.close(master)


@pytest.fixture
def run_env(tmp_path: Path) -> dict[str, str]:
    """A run folder of the test's own, so no lab or tap of another test is seen."""
    return {"KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}


def shipped_lab(tmp_path: Path, edit: dict[str, str]) -> Path:
    """The shipped reference lab, its line and timetable named by absolute path, with the text replacements
    `edit` (old -> new, each old present exactly once) applied."""
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("line: ../lines/reference.yaml", f"line: {line}")
    timetable = (data_dir("emulators") / "timetables" / "reference.yaml").resolve()
    text = text.replace("timetable: ../timetables/reference.yaml", f"timetable: {timetable}")
    for old, new in edit.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "lab.yaml"
    path.write_text(text, encoding="utf-8")
    return path
