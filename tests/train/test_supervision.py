"""ATP supervision, dynamics, MRSP, position and resources: behaviour named by each test."""

from __future__ import annotations

import numpy as np
import pytest

from ktcs_bench.train.curves import CurveTimes, Grid, Target, TargetKind, ebd_distance, ebd_on_grid
from ktcs_bench.train.deceleration import GradientProfile, SafeDeceleration, StepFunction
from ktcs_bench.train.dynamics import Command, TrainDynamics, TrainParams, TrainState
from ktcs_bench.train.mrsp import MODE_LIMITS, Restriction, build_mrsp
from ktcs_bench.train.position import PositionEstimator
from ktcs_bench.train.resources import Resource, ResourceManager
from ktcs_bench.train.supervision import Status, SupervisionLimits, Supervisor
from ktcs_bench.train.units import kmh


def _limits(target: float, decel: float = 1.0) -> SupervisionLimits:
    d = SafeDeceleration(StepFunction.constant(decel))
    g = Grid.uniform(0.0, 5000.0, 1.0, d)
    ebd = ebd_on_grid(g, Target(target), CurveTimes(1.0, 1.0).fixed, 60.0)
    return SupervisionLimits(g.x, ebd, np.full(g.x.shape, kmh(120.0)))


def test_emergency_brake_latches_until_standstill_and_release() -> None:
    sup = Supervisor(CurveTimes(t_be=1.0, t_bs=1.0))
    lim = _limits(1000.0)
    v = sup.check(lim, 995.0, 10.0)
    assert v.emergency_brake and v.status is Status.INTERVENTION
    # far from the target again, but still moving: stays latched
    assert sup.check(lim, 100.0, 5.0).emergency_brake
    # standstill without release: still latched
    assert sup.check(lim, 100.0, 0.0).emergency_brake
    sup.release()
    assert not sup.check(lim, 100.0, 0.0).emergency_brake


def test_release_while_moving_is_ignored() -> None:
    sup = Supervisor(CurveTimes(t_be=1.0, t_bs=1.0))
    lim = _limits(1000.0)
    sup.check(lim, 995.0, 10.0)
    sup.release()
    assert sup.check(lim, 100.0, 3.0).emergency_brake


def test_status_order_along_the_approach() -> None:
    sup = Supervisor(CurveTimes(t_be=2.0, t_bs=2.0, service_brake_command=True))
    lim = _limits(2000.0)
    v = 20.0
    seen = []
    for x in np.arange(1000.0, 2000.0, 2.0):
        st = Supervisor(sup.times).check(lim, float(x), v).status
        if not seen or seen[-1] != st:
            seen.append(st)
    assert seen == [
        Status.NORMAL,
        Status.INDICATION,
        Status.OVERSPEED,
        Status.WARNING,
        Status.INTERVENTION,
    ]


def test_service_brake_disabled_gives_no_service_brake() -> None:
    sup = Supervisor(CurveTimes(2.0, 2.0, service_brake_command=False), service_brake_enabled=False)
    lim = _limits(2000.0)
    # place the train just past SBI but before EBI is impossible with T_bs2 = 0: SBI == EBI
    v = sup.check(lim, 1800.0, 20.0)
    assert not v.service_brake


def test_grid_ebd_matches_exact_integration() -> None:
    d = SafeDeceleration(
        StepFunction((0.0, kmh(50.0)), (1.0, 0.8)),
        GradientProfile((0.0, 3000.0, 3500.0), (0.0, -4.0, 3.0)).compensated(200.0),
    )
    g = Grid.uniform(0.0, 6000.0, 1.0, d)
    t = Target(4000.0, kmh(20.0), TargetKind.SPEED)
    e = ebd_on_grid(g, t, CurveTimes(1, 1).fixed, 60.0)
    for v in (10.0, 20.0, 30.0):
        dist = ebd_distance(d, t, v)
        assert float(np.interp(4000.0 - dist, g.x, e)) == pytest.approx(v, abs=0.02)


def test_compensated_gradient_delays_rises_by_train_length() -> None:
    prof = GradientProfile((0.0, 1000.0, 2000.0), (-2.0, 5.0, -1.0)).compensated(200.0)
    assert prof.at(1100.0) == -2.0  # rear still on the -2 ‰
    assert prof.at(1250.0) == 5.0
    assert prof.at(2000.5) == -1.0  # a fall counts at once


def test_mrsp_holds_lower_limit_one_train_length() -> None:
    p = build_mrsp([Restriction(1000.0, 2000.0, kmh(40.0))], kmh(80.0), 200.0)
    assert p.at(1999.0) == pytest.approx(kmh(40.0))
    assert p.at(2150.0) == pytest.approx(kmh(40.0))
    assert p.at(2201.0) == pytest.approx(kmh(80.0))
    assert [t.location for t in p.targets()] == [1000.0]


def test_mode_limit_caps_the_mrsp() -> None:
    p = build_mrsp([], kmh(160.0), 200.0, mode="staff_responsible")
    assert p.at(10.0) == pytest.approx(MODE_LIMITS["staff_responsible"])


def test_brake_builds_up_over_the_build_up_time() -> None:
    dyn = TrainDynamics(
        TrainParams(brake_build_up=2.0, resistance_a=0, resistance_b=0, resistance_c=0),
        TrainState(speed=20.0),
    )
    dyn.step(0.5, Command(emergency=True))
    assert dyn.state.brake_effort == pytest.approx(dyn.params.emergency_decel / 4.0)
    for _ in range(10):
        dyn.step(0.5, Command(emergency=True))
    assert dyn.state.brake_effort == pytest.approx(dyn.params.emergency_decel)


def test_uphill_gradient_slows_a_coasting_train() -> None:
    flat = TrainDynamics(TrainParams(), TrainState(speed=20.0))
    hill = TrainDynamics(TrainParams(), TrainState(speed=20.0))
    for _ in range(50):
        flat.step(0.1, Command())
        hill.step(0.1, Command(), gradient=10.0)
    assert hill.state.speed < flat.state.speed - 0.4


def test_missed_tag_is_reported() -> None:
    est = PositionEstimator([0.0, 100.0, 200.0, 300.0], 200.0, missed_tags=frozenset({3}))
    est.start(50.0)
    pos, missed = est.advance(50.0, 150.0)
    assert pos.lrti == 2 and not missed
    _, missed = est.advance(150.0, 260.0)
    assert missed == [3]


def test_position_is_last_tag_plus_offset_with_growing_interval() -> None:
    est = PositionEstimator([0.0, 100.0], 200.0, tacho_error=0.01, read_window=1.0)
    est.start(0.0)
    pos, _ = est.advance(0.0, 50.0)
    assert pos.lrti == 1 and pos.offset == pytest.approx(50.5)
    assert pos.uncertainty == pytest.approx(1.0 + 0.505)
    assert pos.tail == pytest.approx(pos.head - 200.0)


def test_resource_manager_commands_point_and_extends_on_detection() -> None:
    rm = ResourceManager(
        [
            Resource("R1", 0, 500),
            Resource("R2", 500, 1000, point="P1", required="reverse"),
            Resource("R3", 1000, 1500),
        ]
    )
    g = rm.request("T1", 100.0, 1500.0, 0.0)
    assert g.authority_end == 500.0 and [c.point for c in g.commands] == ["P1"]
    assert rm.request("T1", 100.0, 1500.0, 1.0).commands == ()  # not commanded twice
    rm.point_detected("P1", "reverse", 4.0)
    assert rm.request("T1", 100.0, 1500.0, 5.0).authority_end == 1500.0


def test_resource_manager_stops_at_other_trains_and_releases_behind() -> None:
    rm = ResourceManager([Resource(f"R{i}", i * 500.0, i * 500.0 + 500.0) for i in range(4)])
    assert rm.request("A", 1100.0, 2000.0, 0.0).authority_end == 2000.0
    assert rm.request("B", 0.0, 2000.0, 0.0).authority_end == 1000.0
    rm.request("A", 1600.0, 2000.0, 1.0)  # A's tail past R2 → R2 released
    assert rm.request("B", 0.0, 2000.0, 2.0).authority_end == 1500.0


def test_grid_curves_agree_with_exact_curve_distances() -> None:
    from ktcs_bench.train.curves import curve_distances, curves_on_grid

    d = SafeDeceleration(StepFunction.constant(1.0))
    g = Grid.uniform(0.0, 3000.0, 1.0, d)
    t = Target(2000.0)
    times = CurveTimes(2.0, 3.0, service_brake_command=True)
    c = curves_on_grid(g, [t], np.full(g.x.shape, 30.0), times, 40.0)
    cd = curve_distances(d, t, times, 20.0)
    for name, dist in (
        ("ebi", cd.ebi),
        ("sbi", cd.sbi2),
        ("warning", cd.warning),
        ("permitted", cd.permitted),
        ("indication", cd.indication),
    ):
        assert float(np.interp(2000.0 - dist, g.x, getattr(c, name))) == pytest.approx(
            20.0, abs=0.05
        )
