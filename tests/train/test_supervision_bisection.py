"""The supervisor's fast limit-speed bisection (inlined look-ups, root shortcut inside one grid
cell) gives bit for bit what the plain bisection over `_limit_speed` gives."""

from __future__ import annotations

import numpy as np
import pytest

from ktcs_bench.train.curves import (
    CurveTimes,
    FixedValues,
    Grid,
    Target,
    TargetKind,
    ebd_min_on_grid,
)
from ktcs_bench.train.deceleration import GradientProfile, SafeDeceleration, StepFunction
from ktcs_bench.train.supervision import SupervisionLimits, Supervisor
from ktcs_bench.train.units import kmh


def _plain(sup: Supervisor, lim: SupervisionLimits, x: float, hi: float, lead: float) -> float:
    lo = 0.0
    if not sup._limit_speed(lim, x, hi, lead, 0.0):
        return hi
    for _ in range(25):
        mid = 0.5 * (lo + hi)
        if sup._limit_speed(lim, x, mid, lead, 0.0):
            hi = mid
        else:
            lo = mid
    return lo


@pytest.mark.parametrize(
    "times",
    [CurveTimes(1.0, 1.0, True, 0.1), CurveTimes(0.0, 0.0), CurveTimes(3.0, 4.0, True, 0.1)],
)
def test_fast_bisection_is_the_plain_bisection(times: CurveTimes) -> None:
    decel = SafeDeceleration(
        StepFunction.constant(1.1), GradientProfile((6200.0,), (-6.0,)).compensated(200.0)
    )
    grid = Grid.uniform(0.0, 8000.0, 1.0, decel)
    targets = [
        Target(7000.3),
        Target(6500.7, kmh(30.0), TargetKind.SPEED),
        Target(6000.2, kmh(60.0), TargetKind.SPEED),
    ]
    ebd = ebd_min_on_grid(grid, targets, FixedValues(), kmh(100.0))
    lim = SupervisionLimits(grid.x, ebd, np.full(grid.x.shape, kmh(80.0)))
    sup = Supervisor(times)
    rng = np.random.default_rng(7)
    for x in np.concatenate((rng.uniform(5500.0, 7100.0, 1500), [-5.0, 0.0, 7999.5])):
        for lead in (0.0, 2.0, 9.0):
            want = _plain(sup, lim, float(x), kmh(90.0), lead)
            assert sup.limit_speed(lim, float(x), kmh(90.0), lead, 25) == want
