"""The supervisor's limit speed (halving until the look-ahead is inside one grid cell past the
same targets, then solved there) is the plain bisection over `_limit_speed` made exact: within
the plain bisection's width of it, never beyond the curve, and beyond one width above — with
look-aheads that pass speed targets and a stop, and targets off the grid's nodes."""

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
from ktcs_bench.train.supervision import EBI, INDICATION, WARNING, SupervisionLimits, Supervisor
from ktcs_bench.train.units import kmh


def _plain(sup: Supervisor, lim: SupervisionLimits, x: float, hi: float, curve: int) -> float:
    lo = 0.0
    if not sup._limit_speed(lim, x, hi, curve, 0.0):
        return hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if sup._limit_speed(lim, x, mid, curve, 0.0):
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
    lim = SupervisionLimits(grid.x, ebd, np.full(grid.x.shape, kmh(80.0)), tuple(targets))
    sup = Supervisor(times)
    rng = np.random.default_rng(7)
    for x in np.concatenate((rng.uniform(5500.0, 7100.0, 1500), [-5.0, 0.0, 7999.5])):
        for curve in (EBI, WARNING, INDICATION):
            want = _plain(sup, lim, float(x), kmh(90.0), curve)
            got = sup.limit_speed(lim, float(x), kmh(90.0), curve, 25)
            width = kmh(90.0) * 2.0**-25
            assert abs(got - want) <= width, (x, curve)
            assert not sup._limit_speed(lim, float(x), got - 1e-9, curve, 0.0), (x, curve)
            if got < kmh(90.0):
                assert sup._limit_speed(lim, float(x), got + width, curve, 0.0), (x, curve)
