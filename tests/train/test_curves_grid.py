"""The vectorised curve set against a plain target-by-target reference.

`curves_on_grid` builds the EBD envelope for all targets at once (suffix order of the curves,
closed form per brake band) and shifts the envelope for EBI/SBI/warning/permitted/indication.
The reference here walks each target separately (`ebd_on_grid`, the band-by-band form) and
shifts each target's own curve before taking the minimum — slow but obviously right. Beyond its
location a target holds each curve at that curve's hold speed (`hold_speeds`: the new MRSP's
ceiling for it, 0 for a stop), so before it a curve with total lead T is also no higher than
max(hold, (L − s)/T): faster, its look-ahead would pass the target (below the speed cap, above
which nothing is supervised).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ktcs_bench.train.curves import (
    CurveBuilder,
    CurveTimes,
    Grid,
    Target,
    TargetKind,
    curves_on_grid,
    ebd_min_on_grid,
    ebd_on_grid,
    hold_speeds,
)
from ktcs_bench.train.deceleration import (
    FloatArray,
    GradientProfile,
    SafeDeceleration,
    StepFunction,
)
from ktcs_bench.train.mrsp import Restriction, build_mrsp
from ktcs_bench.train.units import kmh


def _shifted_reference(x: FloatArray, v: FloatArray, lead: FloatArray) -> FloatArray:
    finite = np.isfinite(v)
    out = np.full(x.shape, np.inf)
    if not finite.any():
        return out
    s, vf = x[finite] - lead[finite], v[finite]
    keep = np.concatenate(([True], np.diff(s) > 0))
    s, vf = s[keep], vf[keep]
    inside = (x >= s[0]) & (x <= s[-1])
    out[inside] = np.interp(x[inside], s, vf)
    out[x > s[-1]] = vf[-1]
    return out


def _reference(
    grid: Grid, targets: list[Target], times: CurveTimes, v_cap: float
) -> dict[str, FloatArray]:
    x, fixed = grid.x, times.fixed
    t_be = times.t_traction + times.t_berem
    leads = {
        "ebi": 0.0,
        "sbi": times.t_bs2,
        "warning": times.t_bs2 + fixed.t_warning,
        "permitted": times.t_bs2 + fixed.t_driver,
        "indication": times.t_bs2 + fixed.t_driver + times.t_indication,
    }
    out = {name: np.full(x.shape, np.inf) for name in ["ebd", *leads]}
    for t in targets:
        e = ebd_on_grid(grid, t, fixed, v_cap)
        np.minimum(out["ebd"], e, out=out["ebd"])
        k = int(np.searchsorted(x, t.location, side="right"))
        before = x < t.location
        for (name, lead), hold in zip(leads.items(), hold_speeds(t, fixed), strict=True):
            if t.kind is TargetKind.STOP:
                out[name][k:] = 0.0
            seg = _shifted_reference(x[:k], e[:k], e[:k] * (t_be + lead))
            np.minimum(out[name][:k], seg, out=out[name][:k])
            if t_be + lead > 0.0:
                bound = np.maximum((t.location - x[before]) / (t_be + lead), hold)
                bound[bound >= v_cap] = np.inf  # nothing above the cap is supervised
                out[name][before] = np.minimum(out[name][before], bound)
    return out


def _line(seed: int, brake: StepFunction, gradients: bool) -> tuple[Grid, list[Target]]:
    rng = np.random.default_rng(seed)
    length = 6000.0
    locs = tuple(float(v) for v in np.sort(rng.uniform(0.0, length, 12)))
    grads = tuple(float(g) if gradients else 0.0 for g in rng.uniform(-15.0, 15.0, 12))
    decel = SafeDeceleration(brake, GradientProfile(locs, grads).compensated(200.0))
    grid = Grid.uniform(0.0, length, 1.0, decel)
    starts = np.sort(rng.uniform(0.0, length - 400.0, 6))
    restr = [
        Restriction(float(a), float(a + rng.uniform(50.0, 700.0)), kmh(float(v)))
        for a, v in zip(starts, rng.uniform(15.0, 120.0, 6), strict=True)
    ]
    targets = build_mrsp(restr, kmh(160.0), 200.0).targets()
    stops = [float(rng.uniform(2000.0, length + 300.0)) for _ in range(1 + seed % 2)]
    targets += [Target(s, 0.0, TargetKind.STOP) for s in stops]
    return grid, targets


BRAKES = {
    "constant": StepFunction.constant(0.9),
    "three bands": StepFunction((0.0, kmh(60.0), kmh(120.0)), (1.1, 1.0, 0.9)),
}


@pytest.mark.parametrize("brake", list(BRAKES))
@pytest.mark.parametrize("gradients", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_grid_curves_match_target_by_target_reference(
    brake: str, gradients: bool, seed: int
) -> None:
    grid, targets = _line(seed, BRAKES[brake], gradients)
    times = CurveTimes(t_be=1.5 + seed, t_bs=2.0 + seed, service_brake_command=seed % 2 == 0)
    v_cap = kmh(180.0) if seed < 3 else math.inf
    ref = _reference(grid, targets, times, v_cap)
    mrsp = np.full(grid.x.shape, np.inf)  # no ceilings: compare the raw curves
    got = curves_on_grid(grid, targets, mrsp, times, v_cap)
    assert np.array_equal(ebd_min_on_grid(grid, targets, times.fixed, v_cap), got.ebd)
    # the band walk interpolates each band crossing linearly inside its grid cell
    tol = 2e-3 if gradients else 1e-6
    for name, want in ref.items():
        have = getattr(got, name)
        near_cap = np.abs(np.where(np.isfinite(want), want, v_cap) - v_cap) < 1e-6
        assert np.array_equal(np.isfinite(want) | near_cap, np.isfinite(have) | near_cap), name
        both = np.isfinite(want) & np.isfinite(have)
        assert float(np.abs(want[both] - have[both]).max()) <= tol, name


def test_h_is_the_exact_gradient_integral() -> None:
    prof = GradientProfile((100.3, 250.7, 900.0), (5.0, -8.0, 2.0), default=-1.0)
    decel = SafeDeceleration(StepFunction.constant(1.0), prof)
    grid = Grid.uniform(50.0, 1000.0, 1.0, decel)
    fine = np.arange(50.0, 1000.0, 0.01) + 0.005
    cum = np.concatenate(([0.0], np.cumsum(decel.gradient_accel_grid(fine) * 0.01)))
    for i in (0, 51, 200, 201, 700, 950):
        assert grid.h[i] == pytest.approx(cum[i * 100], abs=1e-9)
        assert grid.h_at(float(grid.x[i])) == pytest.approx(float(grid.h[i]), abs=1e-9)


@pytest.mark.parametrize("gradients", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_builder_update_is_the_full_rebuild(gradients: bool, seed: int) -> None:
    grid, targets = _line(seed, BRAKES["three bands"], gradients)
    static = [t for t in targets if t.kind is TargetKind.SPEED]
    times = CurveTimes(t_be=1.5 + seed, t_bs=2.0 + seed, service_brake_command=True)
    mrsp = build_mrsp([], kmh(160.0), 200.0).on_grid(grid.x)
    builder = CurveBuilder(grid, static, mrsp, times, kmh(180.0))
    tol = 2e-3 if gradients else 1e-9
    for stop in (-10.0, 0.0, 150.3, 1999.5, 3100.0, 5999.9, 6000.0, 6500.0):
        want = curves_on_grid(grid, [*static, Target(stop)], mrsp, times, kmh(180.0))
        have = builder.update(stop)
        for name in ("ebd", "ebi", "sbi", "warning", "permitted", "indication"):
            a, b = getattr(want, name), getattr(have, name)
            assert np.array_equal(np.isfinite(a), np.isfinite(b)), (stop, name)
            both = np.isfinite(a)
            assert float(np.abs(a[both] - b[both]).max(initial=0.0)) <= tol, (stop, name)
