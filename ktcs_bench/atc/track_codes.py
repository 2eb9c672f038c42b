"""The code a track circuit carries to the train's antenna (seed 004 Fig. 1, SPEC §6.4).

A code is a speed code from the line's table with its target speed, the gradient under the
track circuit (‰, in the direction of travel, the lowest — most adverse for braking — over it),
and the target distance: metres from the track circuit's entry end to the next stop point. A
code is given for one direction of travel (`direction`, SPEC §6.6): a train running the other way
over the track circuit must not read it as its own (`TrackCircuitModel.code_for` gives it the most
restrictive code); None -- the most restrictive code itself -- is for any train.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ktcs_bench.station.model import Direction, Line


@dataclass(frozen=True, slots=True)
class AtcCode:
    code: int
    target_speed_kmh: float
    gradient_permille: float
    target_distance_m: float
    direction: Direction | None = None


def most_restrictive(line: Line, gradient_permille: float = 0.0) -> AtcCode:
    """Stop here: what every track circuit gets while the ATC's IXL link is in error."""
    stop = line.most_restrictive_code
    return AtcCode(stop.code, stop.kmh, gradient_permille, 0.0)


def quantise(line: Line, kmh: float) -> tuple[int, float]:
    """The highest code of the line's table whose speed does not exceed `kmh`."""
    best = line.speed_codes[0]
    for c in line.speed_codes:
        if c.kmh <= kmh + 1e-9:
            best = c
    return best.code, best.kmh


def braking_speed_kmh(distance_m: float, decel_mps2: float) -> float:
    """The speed from which a train stops within `distance_m` at `decel_mps2`."""
    return math.sqrt(2.0 * decel_mps2 * max(distance_m, 0.0)) * 3.6
