"""argparse types shared by the command line and the device builder (`emulator.build`, which a
lab run in one process uses too): counts and rates, HOST:PORT."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from typing import Any

from ktcs_bench.errors import UsageError, excerpt, say_seconds
from ktcs_bench.transport.endpoints import parse_host_port

__all__ = ["duration", "host_port", "positive", "say_seconds", "seconds"]

_DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?|\.\d+)\s*(ms|s|sec|min|m|h)?\s*$")
_UNIT = {"ms": 0.001, "s": 1.0, "sec": 1.0, "min": 60.0, "m": 60.0, "h": 3600.0}


def seconds(value: object, maximum: float | None = None) -> float:
    """A duration as a person writes it -- `90`, `1.5`, `500ms`, `5s`, `2min`, `15m`, `1h` (a
    bare number is seconds) -- in seconds: positive and finite, and at most `maximum` where one
    is given, else ValueError saying so. The one reading of a duration, for the command line and
    the procedure files alike."""
    result = math.nan
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        result = float(value)
    elif isinstance(value, str) and len(value) <= 40:
        try:
            result = float(value)  # a bare number is seconds ("nan", "inf": refused below)
        except ValueError:
            if (m := _DURATION.match(value)) is not None:
                result = float(m.group(1)) * _UNIT[m.group(2) or "s"]
    if not (math.isfinite(result) and result > 0):
        raise ValueError(
            "a duration is a positive number of seconds (or 500ms, 5s, 2min, 1h), "
            f"not {excerpt(value)}"
        )
    if maximum is not None and result > maximum:
        raise ValueError(f"a duration here is at most {say_seconds(maximum)}, not {excerpt(value)}")
    return result


def duration(text: str) -> float:
    """The argparse type of every option that takes a duration (`seconds`)."""
    try:
        return seconds(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


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
