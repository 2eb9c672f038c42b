"""SPEC §9: random MA, MRSP and gradients → a train under ATP (real dynamics, virtual time) never
passes its end of authority and never exceeds its EBD, even with a driver who ignores every limit.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import CycleInputs, LineData, TrainConfig, TrainEndpoint
from ktcs_bench.train.mrsp import Restriction
from ktcs_bench.train.units import kmh

LINE = 4000.0
EBD_TOL = 0.01
"""m/s (0.036 km/h): the 100 ms cycle and the 1 m curve grid leave excursions of ~1 mm/s at a
target's foot; anything larger is a real breach."""


@st.composite
def cases(draw: st.DrawFn) -> tuple[float, list[Restriction], GradientProfile, float, float]:
    eoa = draw(st.floats(700.0, LINE - 100.0))
    n = draw(st.integers(0, 3))
    restrictions = []
    for _ in range(n):
        a = draw(st.floats(250.0, LINE - 300.0))
        b = a + draw(st.floats(50.0, 800.0))
        restrictions.append(Restriction(a, b, kmh(draw(st.floats(15.0, 80.0)))))
    locs = sorted(draw(st.lists(st.floats(0.0, LINE), max_size=4, unique=True)))
    grads = [draw(st.floats(-20.0, 20.0)) for _ in locs]
    build_up = draw(st.floats(0.3, 3.0))
    speed = draw(st.floats(30.0, 120.0))
    return eoa, restrictions, GradientProfile(tuple(locs), tuple(grads)), build_up, speed


@pytest.mark.requirement("TRAIN-ATP-04", "TRAIN-ATP-02")
@settings(max_examples=25, deadline=None)
@given(cases())
def test_never_past_eoa_never_above_ebd(
    case: tuple[float, list[Restriction], GradientProfile, float, float],
) -> None:
    eoa, restrictions, gradient, build_up, top = case
    params = TrainParams(max_speed=kmh(top), brake_build_up=build_up, max_traction=kmh(4.0))
    line = LineData(LINE, [i * 100.0 for i in range(41)], gradient, restrictions)
    cfg = TrainConfig(
        "T",
        params,
        start=params.length + 1.0,
        driver_speed=kmh(top + 30.0),
        inattentive_until_eb=True,
        eb_release_delay=None,
        service_brake_enabled=False,
    )
    train = TrainEndpoint(cfg, line)
    inputs = CycleInputs(authority_end=eoa)
    now = 0.0
    moved = False
    for _ in range(6000):
        train.step(now, inputs)
        now += 0.1
        s = train.state
        assert s.position <= eoa + 1e-6, f"passed the EoA {eoa:.1f} at {s.position:.2f}"
        ebd = train.limits.ebd_at(s.position)
        assert s.speed <= ebd + EBD_TOL, (
            f"speed {s.speed:.2f} above EBD {ebd:.2f} at {s.position:.1f}"
        )
        moved = moved or s.speed > 1.0
        if moved and s.speed <= 0.0 and train.supervisor.eb_latched:
            break
