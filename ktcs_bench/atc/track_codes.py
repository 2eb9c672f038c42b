"""The code a track circuit carries to the train's antenna (seed 004 Fig. 1, SPEC §6.4).

A code is a speed code from the line's table with its target speed, the gradient under the
track circuit (‰, in the direction of travel, the lowest — most adverse for braking — over it),
and the target distance: metres from the track circuit's entry end to the next stop point.

The code steps are graded (`braking_decel`, `braking_speed_kmh`): a code's speed is one from which
a train brakes down to the next circuit's code over that circuit, on the line's service rate
corrected for the most adverse gradient to the stop point in its running direction, after running
on for the line's brake build-up time -- so that the step a train meets at each circuit's entry is
one its ATP's curves on that gradient let it brake for.

A code is given for one direction of travel (`direction`, SPEC §6.6): a train running the other way
over the track circuit must not read it as its own (`TrackCircuitModel.code_for` gives it the most
restrictive code); None -- the most restrictive code itself -- is for any train.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ktcs_bench.station.model import Direction, Line
from ktcs_bench.train.deceleration import RotatingMass, gradient_acceleration


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


def braking_decel(line: Line, gradient_permille: float) -> float:
    """The deceleration the codes are graded with over a stretch whose most adverse gradient is
    `gradient_permille` (running direction, rising positive), m/s²: the line's service rate plus
    what the gradient adds, g·grad/(1000 + 10·M_R) with the rotating-mass allowance the onboard
    ATP takes (`RotatingMass`: the least on a descent, the most on a rise). 0 or less: no
    braking to grade with."""
    return line.service_brake_mps2 + gradient_acceleration(gradient_permille, RotatingMass())


def braking_speed_kmh(
    distance_m: float, decel_mps2: float, build_up_s: float = 0.0, exit_kmh: float = 0.0
) -> float:
    """The highest speed (km/h) from which a train running on for `build_up_s` before braking
    at `decel_mps2` is down to `exit_kmh` within `distance_m`: v·T + (v² − w²)/(2a) = d. A train
    already at `exit_kmh` need not brake, and one that cannot brake (a ≤ 0) may not be faster."""
    w = exit_kmh / 3.6
    if decel_mps2 <= 0.0:
        return exit_kmh
    a, d = decel_mps2, max(distance_m, 0.0)
    at = a * build_up_s
    v = -at + math.sqrt(at * at + w * w + 2.0 * a * d)
    return max(v, w) * 3.6
