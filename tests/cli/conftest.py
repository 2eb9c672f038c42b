"""The `ktcs-bench` command as a user runs it: a real subprocess, its exit code and its words."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir


def cli(
    *args: str, env: dict[str, str] | None = None, timeout: float = 60
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args], capture_output=True, text=True,
        timeout=timeout, env={**os.environ, **(env or {})},
    )  # fmt: skip


@pytest.fixture
def run_env(tmp_path: Path) -> dict[str, str]:
    """A run folder of the test's own, so no lab or tap of another test is seen."""
    return {"KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}


def shipped_lab(tmp_path: Path, edit: dict[str, str]) -> Path:
    """The shipped reference lab, its line named by absolute path, with the text replacements
    `edit` (old -> new, each old present exactly once) applied."""
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("line: ../lines/reference.yaml", f"line: {line}")
    for old, new in edit.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "lab.yaml"
    path.write_text(text, encoding="utf-8")
    return path
