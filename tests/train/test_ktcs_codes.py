"""The train endpoint owns the kTCS code semantics (SPEC §6.4, §6.5): a code's speed holds at its
track circuit's exit, its target distance locates the stop point, and its gradient is the one to
brake on. The line data the train carries here knows no speed limit and no gradient: whatever it
must obey comes from the codes, as the wayside ATC steps them down ahead of a restriction and a
stop point.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import (
    CycleInputs,
    LineData,
    TrackCode,
    TrainConfig,
    TrainEndpoint,
)
from ktcs_bench.train.units import kmh, to_kmh

LINE = 3000.0
TAGS = [i * 100.0 for i in range(31)]


def _line() -> LineData:
    return LineData(LINE, TAGS, GradientProfile(), [])  # no speed limits, flat: codes only


def _codes(
    circuits: list[tuple[float, float, float]], stop: float, gradient: float = 0.0
) -> Callable[[float], TrackCode]:
    """The code under an antenna at x: (entry, exit, speed at the exit in km/h) per circuit,
    each with the distance from its entry to `stop`."""

    def code_at(x: float) -> TrackCode:
        for a, b, v in circuits:
            if a <= x < b:
                return TrackCode.read(a, b, kmh(v), gradient, stop - a)
        return TrackCode.stop_here(x)

    return code_at


def _run(
    train: TrainEndpoint, code_at: Callable[[float], TrackCode], true_gradient: float = 0.0
) -> list[tuple[float, float, str]]:
    """Steps the train until it stands again after moving: (front, speed, status) per cycle."""
    trace = []
    now, moved = 0.0, False
    for _ in range(6000):
        x = train.state.position
        train.step(now, CycleInputs(code=code_at(x), gradient=true_gradient))
        now += 0.1
        s = train.state
        trace.append((s.position, s.speed, train.status.value))
        moved = moved or s.speed > 1.0
        if moved and s.speed <= 0.0:
            break
    return trace


# A 30 km/h stretch [1400, 1800) the train's own data does not know: the ATC gives the circuit
# before it 30 (the speed at its exit) and the stretch itself 30; a stop point at 2800 (the last
# circuit's code is 0, stop at its exit).
CIRCUITS = [
    (0.0, 1000.0, 80.0),
    (1000.0, 1400.0, 30.0),
    (1400.0, 1800.0, 30.0),
    (1800.0, 2400.0, 80.0),
    (2400.0, 2800.0, 0.0),
]


def test_a_code_speed_holds_at_the_exit_of_its_track_circuit() -> None:
    """A ceiling-only reading of the 30 code lets the train through the circuit at the speed it
    entered with (80) and onto the 30 km/h stretch at that speed (or, read as a ceiling from
    the entry, trips the emergency brake there): the train must come down to 30 by the exit,
    on its service brake, and still reach its stop point."""
    cfg = TrainConfig("T", TrainParams(length=100.0, max_speed=kmh(80.0)), start=150.0, mode="ktcs")
    train = TrainEndpoint(cfg, _line())
    trace = _run(train, _codes(CIRCUITS, 2800.0))
    on_stretch = [v for x, v, _ in trace if 1400.0 <= x < 1800.0]
    before = [v for x, v, _ in trace if 600.0 <= x < 1000.0]
    assert on_stretch and before
    assert to_kmh(max(before)) > 70.0, "the train ran at speed before the step (80 code)"
    assert to_kmh(max(on_stretch)) <= 30.0, (
        f"{to_kmh(max(on_stretch)):.1f} km/h past the exit of a 30 code"
    )
    assert train.eb_count == 0, "a driver on the permitted speed never meets the EBI"
    front = trace[-1][0]
    assert 2700.0 < front <= 2800.0, f"stopped at {front:.1f} m (stop point 2800 m)"


def test_the_ceiling_inside_a_circuit_is_the_speed_it_was_entered_with() -> None:
    """Inside the circuit whose code steps down, the train may still run at the speed of the
    code before (the exit speed of the previous circuit): no intervention on entering it."""
    cfg = TrainConfig("T", TrainParams(length=100.0, max_speed=kmh(80.0)), start=150.0, mode="ktcs")
    train = TrainEndpoint(cfg, _line())
    trace = _run(train, _codes(CIRCUITS, 2800.0))
    entering = [(v, st) for x, v, st in trace if 1000.0 <= x < 1020.0]
    assert entering and to_kmh(max(v for v, _ in entering)) > 60.0
    assert all(st in ("normal", "indication") for _, st in entering), entering


def test_the_code_gradient_brakes_the_train_before_the_stop_point() -> None:
    """The line falls at 25 ‰ towards a stop point at 2600 m; only the codes say so. A train
    whose driver ignores every limit is stopped by the ATP alone: braking on the code's gradient
    it stands before the stop point. Read as a ceiling, the 0 code of the last 200 m comes too
    late for an emergency stop from line speed; a curve on a flat line brakes too late."""
    params = TrainParams(length=100.0, max_speed=kmh(80.0), brake_build_up=1.0)
    cfg = TrainConfig(
        "T",
        params,
        start=150.0,
        mode="ktcs",
        driver_speed=kmh(80.0),
        inattentive_until_eb=True,
        eb_release_delay=None,
        service_brake_enabled=False,
    )
    train = TrainEndpoint(cfg, _line())
    circuits = [(0.0, 2400.0, 80.0), (2400.0, 2600.0, 0.0)]
    trace = _run(train, _codes(circuits, 2600.0, gradient=-25.0), true_gradient=-25.0)
    assert train.eb_count == 1, "the ATP had to intervene"
    top = max(v for _, v, _ in trace)
    assert to_kmh(top) > 75.0, "the train was at line speed when the ATP intervened"
    front = max(x for x, _, _ in trace)
    assert front <= 2600.0, f"overran the stop point 2600 m: front at {front:.1f} m"
    assert trace[-1][1] == 0.0 and math.isfinite(front)


def test_no_code_means_stop_here() -> None:
    """A train that reads no code stops where it stands: an intervention at once if moving."""
    cfg = TrainConfig("T", TrainParams(length=100.0, max_speed=kmh(80.0)), 150.0, mode="ktcs")
    train = TrainEndpoint(cfg, _line())
    codes = _codes([(0.0, LINE, 80.0)], LINE)
    now = 0.0
    while train.state.speed < kmh(40.0):
        train.step(now, CycleInputs(code=codes(train.state.position)))
        now += 0.1
    train.step(now, CycleInputs(code=TrackCode.stop_here(train.state.position)))
    assert train.supervisor.eb_latched


def test_the_train_process_passes_codes_on_as_read_and_stops_on_a_bad_one() -> None:
    """The train process hands the endpoint each code located on its track circuit, as read:
    the 30 after an 80 stays 30 (its meaning is the endpoint's). A code it cannot read — wrong
    shape, not a number, NaN or infinite (Python's json reads both), negative — is no code: the
    train stops where it stands, and says why."""
    from ktcs_bench.emulator.train import TrainDevice
    from ktcs_bench.station import load_line
    from ktcs_bench.transport.endpoints import parse_endpoint

    line = load_line()
    cfg = TrainConfig("T1", TrainParams(length=100.0), start=300.0, mode="ktcs")
    dev = TrainDevice("train1", line, cfg, parse_endpoint("tcp://127.0.0.1:9"))
    dev._from_rails({"code": [5, 80, 0.0, 1100], "tc": "TC1851"})
    dev._from_rails({"code": [3, 30, -2.5, 600], "tc": "TC1853A"})
    assert dev.code == TrackCode.read(500.0, 600.0, kmh(30.0), -2.5, 600.0)
    assert dev.rails.connected is False  # so the endpoint is told to stop meanwhile
    assert dev._code_now() == TrackCode.stop_here(dev.endpoint.state.position)
    for bad in (
        [3, 30, 0.0],
        [3, "30", 0.0, 600],
        [3, float("nan"), 0.0, 600],
        [3, 30, float("inf"), 600],
        [3, -5, 0.0, 600],
        [3, 30, 0.0, -1],
        {"speed": 30},
    ):
        dev._from_rails({"code": [3, 30, 0.0, 600], "tc": "TC1853A"})
        assert dev.code is not None
        dev._from_rails({"code": bad, "tc": "TC1853A"})
        assert dev.code is None, bad
        assert dev.events[-1]["kind"] == "bad_code"
