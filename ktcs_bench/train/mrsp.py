"""The most restrictive speed profile (MRSP) and the targets it gives (seeds 000, 003).

Owns combining speed restrictions — permanent and temporary line limits, the train's maximum and
temporary train limits, and the ETCS mode limits of seed 003 Table 1 — into one step profile,
holding every lower limit for one train length past its end (the train's rear must clear it before
the front may speed up). The speed decreases of the result are the MRSP targets of the curves.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ktcs_bench.errors import UsageError
from ktcs_bench.train.curves import Target, TargetKind
from ktcs_bench.train.deceleration import FloatArray
from ktcs_bench.train.units import kmh

MODE_LIMITS: dict[str, float] = {
    "full_supervision": math.inf,
    "shunting": kmh(30.0),
    "staff_responsible": kmh(40.0),
    "on_sight": kmh(30.0),
    "unfitted": kmh(100.0),
}
"""ETCS mode speed limits of seed 003 Table 1, m/s."""


@dataclass(frozen=True)
class Restriction:
    """A speed limit over [start, end) on the line, m/s."""

    start: float
    end: float
    speed: float

    def __post_init__(self) -> None:
        if self.end <= self.start:
            raise UsageError(f"restriction end {self.end} must lie after its start {self.start}")
        if self.speed < 0:
            raise UsageError("restriction speed must not be negative")


@dataclass(frozen=True)
class SpeedProfile:
    """Step profile: `speeds[i]` from `starts[i]` up to the next start; beyond the last: its value."""

    starts: tuple[float, ...]
    speeds: tuple[float, ...]

    def at(self, x: float) -> float:
        i = bisect.bisect_right(self.starts, x) - 1
        return self.speeds[max(i, 0)]

    def on_grid(self, x: FloatArray) -> FloatArray:
        """The profile at every location of the sorted array `x` (before the first start: the
        first speed). One pass: the starts are located in `x` and each speed repeated."""
        edges = x.searchsorted(np.asarray(self.starts[1:]), side="left")
        counts = np.diff(edges, prepend=0, append=len(x))
        out: FloatArray = np.repeat(np.asarray(self.speeds, dtype=np.float64), counts)
        return out

    def targets(self) -> list[Target]:
        """Every speed decrease, as a SPEED target at the location of the decrease."""
        out = []
        for i in range(1, len(self.starts)):
            if self.speeds[i] < self.speeds[i - 1]:
                out.append(Target(self.starts[i], self.speeds[i], TargetKind.SPEED))
        return out


def build_mrsp(
    restrictions: Iterable[Restriction],
    train_max_speed: float,
    train_length: float,
    mode: str = "full_supervision",
    line_start: float = 0.0,
    line_end: float = math.inf,
) -> SpeedProfile:
    """Minimum of every restriction, the train maximum and the mode limit, length-extended."""
    if mode not in MODE_LIMITS:
        raise UsageError(f"unknown mode {mode!r} (one of {', '.join(MODE_LIMITS)})")
    base = min(train_max_speed, MODE_LIMITS[mode])
    # Each restriction's end is held one train length further (rear must clear it).
    rs = [Restriction(r.start, r.end + train_length, r.speed) for r in restrictions]
    points = sorted({line_start} | {r.start for r in rs} | {r.end for r in rs})
    points = [p for p in points if p >= line_start and p < line_end]
    starts: list[float] = []
    speeds: list[float] = []
    for i, p in enumerate(points):
        nxt = points[i + 1] if i + 1 < len(points) else p + 1.0
        mid = 0.5 * (p + nxt)
        v = min([base] + [r.speed for r in rs if r.start <= mid < r.end])
        if not speeds or v != speeds[-1]:
            starts.append(p)
            speeds.append(v)
    return SpeedProfile(tuple(starts), tuple(speeds))


def profile_from_sections(
    sections: Sequence[tuple[float, float]], start: float = 0.0
) -> list[Restriction]:
    """(length, speed) sections laid end to end from `start` → restrictions."""
    out = []
    x = start
    for length, speed in sections:
        out.append(Restriction(x, x + length, speed))
        x += length
    return out
