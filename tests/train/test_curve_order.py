"""Supervision curves keep their order (SPEC §6.5): at every place, permitted ≤ warning ≤ SBI ≤
EBI, for random MRSPs, stop targets, gradients, brake models and train timings — in the curve
set drawn over the grid, in the supervisor's own verdicts (a speed past a curve is past every
curve with a longer lead), and in the limit speeds the reports sample.

Before the look-ahead was held at each target it passes, a look-ahead that jumped past an MRSP
decrease read the next target's higher curve: the seed 003 plot had SBI and warning above EBI
before the 90 → 60 step and saw-teeth before every decrease.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.train.curves import CurveTimes, Grid, Target, TargetKind, curves_on_grid
from ktcs_bench.train.deceleration import GradientProfile, SafeDeceleration, StepFunction
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import LineData, TrackCode, TrainConfig, TrainEndpoint
from ktcs_bench.train.mrsp import Restriction, build_mrsp
from ktcs_bench.train.supervision import EBI, INDICATION, PERMITTED, SBI, WARNING
from ktcs_bench.train.units import kmh

LINE = 3000.0
ORDER = ("ebi", "sbi", "warning", "permitted", "indication")


@st.composite
def lines(draw: st.DrawFn) -> tuple[list[Restriction], GradientProfile, list[float]]:
    """Restrictions (15–120 km/h), a gradient profile (±20 ‰) and 1–2 stop targets; locations
    on and off the 1 m grid's nodes."""
    restrictions = []
    for _ in range(draw(st.integers(0, 4))):
        a = draw(st.floats(100.0, LINE - 300.0))
        b = a + draw(st.floats(20.0, 900.0))
        restrictions.append(Restriction(a, b, kmh(draw(st.floats(15.0, 120.0)))))
    locs = sorted(draw(st.lists(st.floats(0.0, LINE), max_size=5, unique=True)))
    gradient = GradientProfile(tuple(locs), tuple(draw(st.floats(-20.0, 20.0)) for _ in locs))
    stops = draw(st.lists(st.floats(600.0, LINE + 200.0), min_size=1, max_size=2))
    return restrictions, gradient, stops


brakes = st.sampled_from(
    [
        StepFunction.constant(0.7),
        StepFunction.constant(1.1),
        StepFunction((0.0, kmh(60.0), kmh(120.0)), (1.1, 1.0, 0.9)),
    ]
)
timings = st.builds(
    CurveTimes,
    t_be=st.floats(0.0, 4.0),
    t_bs=st.floats(0.0, 5.0),
    service_brake_command=st.booleans(),
    t_traction=st.sampled_from([0.0, 0.1]),
)


@settings(max_examples=40, deadline=None)
@given(lines(), brakes, timings)
def test_every_curve_set_keeps_the_order_at_every_place(
    line: tuple[list[Restriction], GradientProfile, list[float]],
    brake: StepFunction,
    times: CurveTimes,
) -> None:
    restrictions, gradient, stops = line
    decel = SafeDeceleration(brake, gradient.compensated(200.0))
    grid = Grid.uniform(0.0, LINE, 1.0, decel)
    mrsp = build_mrsp(restrictions, kmh(160.0), 200.0)
    targets = mrsp.targets() + [Target(s, 0.0, TargetKind.STOP) for s in stops]
    cs = curves_on_grid(grid, targets, mrsp.on_grid(grid.x), times, kmh(180.0))
    curves = [cs.ebd, cs.ebi, cs.sbi, cs.warning, cs.permitted, cs.indication]
    names = ["ebd", *ORDER]
    for (hi_name, hi), (lo_name, lo) in zip(
        zip(names, curves, strict=True), zip(names[1:], curves[1:], strict=True), strict=False
    ):
        bad = np.flatnonzero(lo > hi)
        assert bad.size == 0, (
            f"{lo_name} above {hi_name} at {cs.x[bad[0]]:.0f} m: "
            f"{lo[bad[0]] * 3.6:.3f} > {hi[bad[0]] * 3.6:.3f} km/h"
        )


def _endpoint(
    line: tuple[list[Restriction], GradientProfile, list[float]],
    build_up: float,
    code: tuple[float, float, float, float] | None,
) -> TrainEndpoint:
    restrictions, gradient, stops = line
    params = TrainParams(max_speed=kmh(120.0), brake_build_up=build_up)
    mode = "atcs" if code is None else "ktcs"
    cfg = TrainConfig("T", params, start=params.length + 1.0, mode=mode)
    train = TrainEndpoint(cfg, LineData(LINE, [], gradient, restrictions))
    kcode = None
    if code is not None:
        start, length, speed, grad = code
        kcode = TrackCode.read(start, start + length, kmh(speed), grad, stops[0] - start)
    train._rebuild(min(stops), kcode)
    return train


codes = st.none() | st.tuples(
    st.floats(0.0, 1500.0), st.floats(50.0, 800.0), st.floats(0.0, 110.0), st.floats(-20.0, 20.0)
)


@settings(max_examples=40, deadline=None)
@given(lines(), st.floats(0.3, 3.0), codes, st.data())
def test_past_a_curve_is_past_every_later_one(
    line: tuple[list[Restriction], GradientProfile, list[float]],
    build_up: float,
    code: tuple[float, float, float, float] | None,
    data: st.DataObject,
) -> None:
    """The supervisor's own verdict, at random places and speeds (with a kTCS code's targets laid
    over the line's): the curves a train is past are EBI ⇒ SBI ⇒ warning ⇒ permitted ⇒
    indication, never a later one without an earlier one reversed."""
    train = _endpoint(line, build_up, code)
    sup, lim = train.supervisor, train.limits
    xs = data.draw(st.lists(st.floats(0.0, LINE), min_size=20, max_size=20))
    for x in xs:
        for v in np.linspace(0.0, kmh(140.0), 57):
            past = [sup._limit_speed(lim, x, float(v), c, 0.0) for c in range(5)]
            assert past == sorted(past), (x, float(v) * 3.6, past)


@settings(max_examples=30, deadline=None)
@given(lines(), st.floats(0.3, 3.0), codes, st.data())
def test_limit_speeds_keep_the_order_computed_each_on_its_own(
    line: tuple[list[Restriction], GradientProfile, list[float]],
    build_up: float,
    code: tuple[float, float, float, float] | None,
    data: st.DataObject,
) -> None:
    """Each curve's limit speed sought on its own from its own ceiling (no bound from the curve
    before it): EBI ≥ SBI ≥ warning ≥ permitted ≥ indication at every place, to the bisection's
    width."""
    train = _endpoint(line, build_up, code)
    sup, lim, f = train.supervisor, train.limits, train.times.fixed
    xs = data.draw(st.lists(st.floats(0.0, LINE), min_size=30, max_size=30))
    top = kmh(200.0)
    for x in xs:
        v_mrsp = lim.mrsp_at(x)
        ceilings = [
            v_mrsp + f.dv_ebi(v_mrsp),
            v_mrsp + f.dv_sbi(v_mrsp),
            v_mrsp + f.dv_warning(v_mrsp),
            v_mrsp,
            v_mrsp,
        ]
        limits = [
            sup.limit_speed(lim, x, min(c, top), curve, 30)
            for curve, c in zip((EBI, SBI, WARNING, PERMITTED, INDICATION), ceilings, strict=True)
        ]
        for a, b in zip(limits, limits[1:], strict=False):
            assert b <= a + top * 2.0**-30, (x, [round(v * 3.6, 4) for v in limits])
        assert all(math.isfinite(v) for v in limits)
