"""The capture record (one frame or span of bytes, when, which way) and direction helpers.

A direction is a string: `a>b` (from endpoint a to endpoint b, e.g. `ixl>atc`), or a console's `rx`/`tx`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

# What the hex-text parser accepts as a direction word (ktcs_bench.codec.hextext._HEXLOG).
DIRECTION_RE = re.compile(r"^[A-Za-z][\w.>-]*$")


@dataclass(frozen=True, slots=True)
class CaptureRecord:
    """One recorded frame (or span of bytes) and its time in seconds (epoch when live), or None."""

    time: float | None
    direction: str
    data: bytes


def split_direction(direction: str) -> tuple[str, str] | None:
    """`a>b` (or `a->b`) -> ("a", "b"); anything else -> None."""
    d = direction.replace("->", ">")
    if d.count(">") != 1:
        return None
    src, dst = d.split(">")
    if not src or not dst:
        return None
    return src, dst


def normalise_direction(direction: str) -> str:
    """`a->b` -> `a>b`; other words are kept as they are."""
    pair = split_direction(direction)
    return f"{pair[0]}>{pair[1]}" if pair else direction


def reverse_direction(direction: str) -> str:
    """The other way: `a>b` -> `b>a`, `tx` <-> `rx`; any other word -> `reply`."""
    pair = split_direction(direction)
    if pair:
        return f"{pair[1]}>{pair[0]}"
    return {"tx": "rx", "rx": "tx"}.get(direction, "reply")


def valid_direction(direction: str) -> bool:
    """A direction the hex log can carry (no spaces, starts with a letter, is not hex)."""
    return bool(DIRECTION_RE.match(direction)) and not re.fullmatch(r"[0-9a-fA-F]+", direction)
