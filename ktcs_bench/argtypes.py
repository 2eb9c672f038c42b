"""argparse types shared by the command line and the device builder (`emulator.build`, which a
lab run in one process uses too): counts and rates, HOST:PORT."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

from ktcs_bench.errors import UsageError
from ktcs_bench.transport.endpoints import parse_host_port

__all__ = ["host_port", "positive"]


def positive(kind: type[int] | type[float], minimum: float = 1) -> Callable[[str], Any]:
    """The argparse type of a count or rate (`--baud`, `--count`, `--retry-count`, ...): a finite
    number of `kind`, at least `minimum` (0 for a count where none is meaningful)."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value) or value < minimum:
            what = "a whole number" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"must be {what} ≥ {minimum:g}, not {text!r}")
        return value

    return parse


def host_port(any_free: bool = False) -> Callable[[str], tuple[str, int]]:
    """The argparse type of a HOST:PORT option -> (host, port); `any_free`: port 0 allowed."""

    def parse(text: str) -> tuple[str, int]:
        try:
            return parse_host_port(text, any_free=any_free)
        except UsageError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse
