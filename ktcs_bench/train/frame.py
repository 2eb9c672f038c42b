"""The line as a train running one way sees it: one coordinate, the distance run in its direction.

The onboard (dynamics, ATP, ATO: `train.endpoint`) works in rising positions only. A train
running up (rising chainage) sees the chainage as it is; a train running down sees the line
mirrored, `s = start + end - x`, so its line spans the same [start, end] and it runs from low s
to high s all the same. `Frame` owns that mapping and nothing else: chainage to the train's
coordinate and back, a stretch [a, b) of the line as the train meets it (its entry end first),
gradients (a rise up is a fall down: mirrored and negated), speed limits, tags and the codes of
track circuits (their target distance counts from the end the train enters by). Sans-I/O: plain
numbers in, plain numbers out; the train process maps its line with it once and maps each
position it reports back to chainage.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from ktcs_bench.errors import UsageError
from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.endpoint import TrackCode
from ktcs_bench.train.mrsp import Restriction

Sense = Literal["up", "down"]
"""The direction a train runs: up = rising chainage (the station data's `Direction`)."""


@dataclass(frozen=True)
class Frame:
    """A line [start, end] (chainage, m) as a train running `sense` sees it (module docstring)."""

    start: float
    end: float
    sense: Sense = "up"

    def __post_init__(self) -> None:
        if self.sense not in ("up", "down"):
            raise UsageError(f"a train runs up or down, not {self.sense!r}")
        if not self.start < self.end:
            raise UsageError(f"a line runs from a lower to a higher chainage, not {self}")

    @property
    def mirrored(self) -> bool:
        """The train's coordinate runs against the chainage (a down train)."""
        return self.sense == "down"

    def s(self, x: float) -> float:
        """Chainage `x` as the train's coordinate."""
        return self.start + self.end - x if self.mirrored else x

    def x(self, s: float) -> float:
        """The train's coordinate `s` as chainage (the mirror is its own inverse)."""
        return self.s(s)

    def span(self, a: float, b: float) -> tuple[float, float]:
        """Stretch [a, b] of chainage (a ≤ b) in the train's coordinate: (the end it enters by,
        the end it leaves by)."""
        return (self.s(b), self.s(a)) if self.mirrored else (a, b)

    def gradient(self, segments: Iterable[tuple[float, float, float]]) -> GradientProfile:
        """The line's gradients (from_m, to_m, ‰ rising up) as the train climbs them: each
        stretch mirrored, a rise up a fall down. Where the table is silent between two
        stretches, and past the last, the gradient is 0 (as the line data read it)."""
        mine = sorted(
            (*self.span(a, b), (-g if self.mirrored else g) + 0.0)  # + 0.0: no -0.0
            for a, b, g in segments
            if a < b
        )
        locations: list[float] = []
        values: list[float] = []
        for i, (lo, _hi, g) in enumerate(mine):
            if i and lo > mine[i - 1][1]:  # a gap after the stretch before: level
                locations.append(mine[i - 1][1])
                values.append(0.0)
            if locations and lo <= locations[-1]:
                raise UsageError(f"gradient stretches overlap at {self.x(lo):g} m")
            locations.append(lo)
            values.append(g)
        if mine and mine[-1][1] < self.end:  # past the last stretch: level
            locations.append(mine[-1][1])
            values.append(0.0)
        return GradientProfile(tuple(locations), tuple(values))

    def restrictions(self, limits: Iterable[tuple[float, float, float]]) -> list[Restriction]:
        """Speed limits (from_m, to_m, m/s) over the stretches the train runs through."""
        return [Restriction(*self.span(a, b), v) for a, b, v in limits]

    def tags(self, locations: Iterable[float]) -> list[float]:
        """Tag locations in the order the train passes them."""
        return sorted({self.s(x) for x in locations})

    def code(
        self,
        from_m: float,
        to_m: float,
        speed: float,
        gradient: float,
        target_distance: float | None,
    ) -> TrackCode:
        """The code of track circuit [from_m, to_m) located for the train: it is entered by
        the end the train meets first and the target distance counts from there. The code's
        gradient is already in the direction of travel (the wayside grades it so)."""
        entry, exit_ = self.span(from_m, to_m)
        return TrackCode.read(entry, exit_, speed, gradient, target_distance)
