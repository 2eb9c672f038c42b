"""An ATO-driven train held by kTCS codes brakes within its ATP's curves (SPEC §6.4, §6.5): the
ATP's service-brake intervention (SBI), let alone its emergency brake, is for a train driven
wrong, never for one its ATO drives on the codes. The ATO plans each target the ATP supervises on
a deceleration its service brake gives net of the code's gradient, with the brake demand carrying
that gradient, and ends its braking the margin short of the target that the SBI's lead needs.

All on the virtual clock: the train endpoint stepped cycle by cycle, codes located on the line as
the wayside ATC gave them before its code steps were graded with the gradient and the brake
build-up (a speed at each circuit's exit, sized at the line's service brake rate on the level, a
stop at the exit of the last free circuit): the ATO must cope with those too. The real wayside's
graded codes are driven in `tests/atc/test_code_grading_property.py`.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.atc.track_codes import braking_speed_kmh, quantise
from ktcs_bench.station import load_line
from ktcs_bench.train.ato import sbi_margin
from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import CycleInputs, LineData, TrackCode, TrainConfig, TrainEndpoint
from ktcs_bench.train.units import kmh

LINE = load_line()
"""The reference line: its code table and the service brake rate its codes are graded with."""
Circuit = tuple[float, float, float, float]
"""(entry, exit, code speed at the exit in km/h, code gradient ‰)."""


def _codes(lengths: list[float], limits: list[float], gradients: list[float]) -> list[Circuit]:
    """The codes the wayside ATC gives a row of free circuits up to a stop at the last one's
    exit (the next circuit occupied): each circuit's speed at its exit is the next one's limit
    at most, and no more than a service braking over the free distance beyond its exit allows,
    quantised down to the line's code table; the last circuit's code is 0."""
    edges = [0.0]
    for length in lengths:
        edges.append(edges[-1] + length)
    stop = edges[-1]
    out = []
    for i, g in enumerate(gradients):
        a, b = edges[i], edges[i + 1]
        if i == len(lengths) - 1:
            speed = 0.0
        else:
            allowed = min(limits[i], limits[i + 1])
            allowed = min(allowed, braking_speed_kmh(stop - b, LINE.service_brake_mps2))
            speed = quantise(LINE, allowed)[1]
        out.append((a, b, speed, g))
    return out


def _drive(
    circuits: list[Circuit], *, build_up: float = 0.5, top: float = 80.0, start: float = 101.0
) -> tuple[TrainEndpoint, list[tuple[float, str, float, float]]]:
    """An ATO train (100 m, kTCS) from standstill at `start` through `circuits` until it stands
    again: the endpoint and its ATP's brake interventions (time, kind, front, speed km/h). The
    plant runs on the code's gradient under its middle (the line data know none: the codes
    say it all)."""
    stop = circuits[-1][1]
    line = LineData(stop + 500.0, [i * 100.0 for i in range(int(stop // 100.0) + 6)])
    params = TrainParams(length=100.0, max_speed=kmh(top), brake_build_up=build_up)
    cfg = TrainConfig("T", params, start=start, mode="ktcs", ato=True, driver_speed=kmh(top))
    train = TrainEndpoint(cfg, line)
    true = GradientProfile(tuple(c[0] for c in circuits), tuple(c[3] for c in circuits))

    def code_at(x: float) -> TrackCode:
        for a, b, v, g in circuits:
            if a <= x < b:
                return TrackCode.read(a, b, kmh(v), g, stop - a)
        return TrackCode.stop_here(x)

    interventions = []
    now, moved = 0.0, False
    for _ in range(30000):
        x = train.state.position
        out = train.step(now, CycleInputs(code=code_at(x), gradient=true.at(x - 50.0)))
        interventions += [
            (e.time, e.kind, x, train.state.speed * 3.6)
            for e in out.events
            if e.kind in ("service_brake", "emergency_brake")
        ]
        now += 0.1
        moved = moved or train.state.speed > 1.0
        if moved and train.state.speed <= 0.0 and train.service_state(now) == "held":
            break
    return train, interventions


FOLLOWING: list[Circuit] = [
    (0.0, 800.0, 90.0, 8.0),
    (800.0, 1600.0, 90.0, -12.0),
    (1600.0, 2400.0, 0.0, -12.0),
]
"""The procedure train_following's approach, shifted: TC1863, TC1867 and TC2043 of the
reference line with TC2045 occupied ahead -- 90 at the exits of the first two, 0 at the third's,
the last 1.6 km falling at 12 ‰."""


def test_a_train_held_by_a_stop_code_on_a_descent_brakes_within_the_sbi() -> None:
    """The train following another stops short of the occupied circuit on the −12 ‰ descent
    without its ATP intervening. (Its ATO once demanded the deceleration its stop needed
    without the 0.12 m/s² the descent takes off it: it fell behind its own braking, ever later
    for the curves that brake on that descent, and passed the SBI at 28 km/h 41 m before the
    stop, then the EBI at 22 km/h.)"""
    train, interventions = _drive(FOLLOWING)
    assert interventions == []
    assert train.eb_count == 0
    front = train.state.position
    assert 2350.0 < front < 2400.0, f"stood at {front:.1f} m, stop at 2400 m"


def test_a_long_brake_build_up_stops_the_train_short_by_the_margin_the_sbi_needs() -> None:
    """With a 3 s brake build-up the SBI leads the EBD by 6 s at the train's speed: an ATO
    braking at 0.6 m/s² to the stop point itself would pass it at about 45 km/h; it aims the
    margin short instead."""
    train, interventions = _drive([(0.0, 1600.0, 90.0, 0.0), (1600.0, 2400.0, 0.0, 0.0)],
                                  build_up=3.0)  # fmt: skip
    assert interventions == []
    assert train.state.position < 2400.0 - sbi_margin(6.0, 0.6, 10 / 9, 0.0, 0.0)


@st.composite
def _layouts(draw: st.DrawFn) -> tuple[list[Circuit], float, float]:
    n = draw(st.integers(2, 6))
    lengths = [draw(st.floats(200.0, 900.0)) for _ in range(n)]
    limits = [draw(st.sampled_from((45.0, 65.0, 80.0, 110.0))) for _ in range(n)]
    steep = st.sampled_from((-20.0, -12.0, 0.0, 15.0))  # the cases that matter, often
    gradients = [draw(st.one_of(steep, st.floats(-20.0, 20.0))) for _ in range(n)]
    return _codes(lengths, limits, gradients), draw(st.floats(0.3, 2.0)), draw(st.floats(50, 100))


@pytest.mark.requirement("TRAIN-ATP-02")
@settings(max_examples=40, deadline=None)
@given(_layouts())
def test_an_ato_train_on_legal_codes_never_reaches_the_sbi(
    case: tuple[list[Circuit], float, float],
) -> None:
    """Any row of circuits coded as the wayside ATC codes them (speed steps at the exits, a stop
    at the last), any gradients from −20 to +20 ‰, any brake build-up from 0.3 to 2 s, any top
    speed: the ATO drives the train to a stand short of the stop point and its ATP never
    intervenes. (The codes are graded at the line's 0.5 m/s² whatever the gradient: on a
    steeper descent this train's service brake gives too little more than that for the ATO's
    reserve, and a code stepping down at a circuit's entry can ask for more than it has.)"""
    circuits, build_up, top = case
    train, interventions = _drive(circuits, build_up=build_up, top=top)
    assert interventions == []
    stop = circuits[-1][1]
    assert stop - 120.0 < train.state.position < stop
    assert train.state.speed == 0.0


def test_the_sbi_margin_is_the_widest_lead_over_the_planned_braking() -> None:
    """`sbi_margin` is the most the SBI curve (the EBD on the safe deceleration, `lead` s of
    the speed ahead of it) reaches beyond a braking on the planned deceleration, over every
    speed the braking passes."""
    cases: list[tuple[float, float, float, float, float]] = [
        (1.0, 0.6, 1.11, 0.0, 0.0),
        (6.0, 0.6, 1.11, 0.0, 0.0),
        (1.0, 0.4, 0.78, 0.0, 0.0),
        (5.5, 0.5, 1.0, kmh(80.0), kmh(87.5)),
        (1.0, 0.6, 1.11, kmh(30.0), kmh(37.5)),
    ]
    for lead, a_plan, a_safe, v_to, v_foot in cases:
        widest = max(
            lead * v
            + (v * v - v_foot * v_foot) / (2 * a_safe)
            - (v * v - v_to * v_to) / (2 * a_plan)
            for v in (v_to + i * 0.001 for i in range(40000))
        )
        assert math.isclose(sbi_margin(lead, a_plan, a_safe, v_to, v_foot), max(widest, 0.0),
                            abs_tol=1e-5)  # fmt: skip
