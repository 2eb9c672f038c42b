"""Small pieces every subcommand shares: colour on a terminal, the argument types of durations
and ports, JSON lines."""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
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
