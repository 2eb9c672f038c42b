"""Small pieces every subcommand shares: colour on a terminal, the argument types of durations
and ports, JSON lines."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from ktcs_bench.argtypes import duration as duration
from ktcs_bench.argtypes import host_port as host_port
from ktcs_bench.argtypes import positive as positive
from ktcs_bench.capture.printer import print_json_line as print_json_line
from ktcs_bench.errors import UsageError
from ktcs_bench.transport.endpoints import check_port


def use_colour(stream: TextIO, flag: bool | None = None) -> bool:
    """Colour where a person watches: `--colour`/`--no-colour` if given, else a tty and no
    NO_COLOR in the environment (https://no-color.org: set and not empty). `main` decides once,
    for every command, and hands the answer over as `args.colour`."""
    if flag is not None:
        return flag
    return stream.isatty() and not os.environ.get("NO_COLOR")


def port(any_free: bool = False) -> Callable[[str], int]:
    """The argparse type of a port option: 1..65535 (`any_free`: 0 too, any free port)."""

    def parse(text: str) -> int:
        try:
            return check_port(text, any_free=any_free)
        except UsageError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


def output_folder(word: str, option: str) -> Path:
    """A folder reports are written to, checked before anything runs: a folder, or a path to
    one that can be made (made when the reports are written)."""
    path = Path(word)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {word}: is a file, not a folder")
    there = path
    while not there.exists():  # the nearest folder that is there
        there = there.parent
    if not there.is_dir():
        raise UsageError(f"{option} {word}: {there} is a file, not a folder")
    try:
        probe_writable(there)
    except OSError as exc:
        raise UsageError(f"{option} {word}: cannot write in {there}: "
                         f"{exc.strerror or exc}") from None  # fmt: skip
    return path


def probe_writable(folder: Path) -> None:
    """OSError unless a file can be made in `folder` (tried: permissions alone do not say, for
    root, or on a read-only file system)."""
    with tempfile.NamedTemporaryFile(dir=folder, prefix=".ktcs-bench-probe-"):
        pass
