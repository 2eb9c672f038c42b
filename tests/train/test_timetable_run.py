"""A train runs its timetable entry in kTCS mode, on the virtual clock: its ATO stops at each
platform's mark within ±0.5 m, stands its dwell, leaves no sooner than the timetable and the
codes allow, and says what it is doing (running, stopping, dwelling, held, finished).

The wayside here is a stand-in for the ATC: each track circuit's code from where the trains'
stop points are -- the starting signal of a platform (at the exit of its track circuit) while
it is at stop, and the end of the line -- sized as the reference ATC sized them before it graded
its code steps with the gradient and the brake build-up (speed at the exit = what the code table
allows for braking at `service_brake_mps2` to the stop point, the target distance counted from
the circuit's entry). The real ATC and interlocking are in the lab
tests; here the point is the train's logic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.emulator.train import TimetableRun, timetable_run
from ktcs_bench.errors import UsageError
from ktcs_bench.station import load_line
from ktcs_bench.station.model import Line
from ktcs_bench.station.timetable import load_timetable
from ktcs_bench.timed.virtual import VirtualClock
from ktcs_bench.train.endpoint import (
    STOP_TOLERANCE,
    CycleInputs,
    CycleOutputs,
    TrackCode,
    TrainEndpoint,
)
from ktcs_bench.train.units import kmh

TIMETABLE = data_dir("emulators") / "timetables" / "reference.yaml"


@dataclass
class Wayside:
    """Codes on the reference line's track circuits of one station track, from stop points."""

    line: Line
    track: str
    decel: float
    signals: dict[float, bool] = field(default_factory=dict)  # stop point -> at stop

    def stop_points(self) -> list[float]:
        return sorted([x for x, red in self.signals.items() if red] + [self.line.end_m])

    def code(self, head: float, ahead: tuple[float, ...] = ()) -> TrackCode | None:
        """The code under an antenna at `head`; `ahead`: the rears of trains ahead, whose track
        circuits are occupied (a stop point at the entry of each)."""
        speeds = [c.kmh for c in self.line.speed_codes]
        tcs = self.line.all_track_circuits()
        rears = [
            tc.from_m
            for rear in ahead
            for tc in tcs
            if tc.on_track(self.track) and tc.from_m <= rear < tc.to_m and tc.from_m > head
        ]
        for tc in tcs:
            if not (tc.on_track(self.track) and tc.from_m <= head < tc.to_m):
                continue
            stop = next(x for x in sorted([*self.stop_points(), *rears]) if x >= tc.to_m - 1e-6)
            room = max(stop - tc.to_m, 0.0)
            allowed = math.sqrt(2.0 * self.decel * room) * 3.6
            kmh_ = max([v for v in speeds if v <= min(allowed, 80.0)], default=0.0)
            grad = self.line.gradient_between(tc.from_m, tc.to_m)
            return TrackCode.read(tc.from_m, tc.to_m, kmh(kmh_), grad, stop - tc.from_m)
        return None


def run_train(
    train_id: str, release: dict[str, float], until: float
) -> tuple[TrainEndpoint, list[tuple[float, str]], TimetableRun, Wayside]:
    """Run timetable train `train_id` alone; the starting signal of each station turns to
    proceed at `release[station]` (absent: never). Returns the endpoint and its state changes."""
    ep, clock, states, run, wayside = start_train(train_id, release)
    clock.run_until(until)
    return ep, states, run, wayside


def start_train(
    train_id: str, release: dict[str, float]
) -> tuple[TrainEndpoint, VirtualClock, list[tuple[float, str]], TimetableRun, Wayside]:
    """`run_train`'s train on its clock, not run yet."""
    line = load_line()
    entry = load_timetable(TIMETABLE, line).train(train_id)
    run = timetable_run(entry, line, 0.5)
    starting = {}
    for stop in entry.stops:
        st = line.station(stop.station)
        sig = next(s for s in st.signals if s.kind == "starting" and s.track == stop.track)
        starting[str(stop.station)] = sig.position_m
    wayside = Wayside(line, entry.stops[0].track, line.service_brake_mps2)
    clock = VirtualClock()
    ep = TrainEndpoint(run.config, run.line, first=max(0.1, run.enter_s))
    ep.sense = lambda now: CycleInputs(code=wayside.code(ep.state.position))
    states: list[tuple[float, str]] = []

    def record(now: float, out: CycleOutputs | None) -> None:
        if out is None:
            return
        for name, at in starting.items():
            wayside.signals[at] = now < release.get(name, math.inf)
        state = ep.service_state(now + ep.cycle)
        if not states or states[-1][1] != state:
            states.append((now, state))

    for at in starting.values():
        wayside.signals[at] = True
    clock.add(ep, record)
    return ep, clock, states, run, wayside


def test_the_ato_stops_at_each_platform_within_half_a_metre_dwells_and_departs_on_time() -> None:
    ep, states, run, _ = run_train("1001", {"18": 100.0, "20": 330.0}, until=900.0)
    marks = {s.name: s for s in run.line.stations}
    assert [a.station for a in ep.arrivals] == ["18", "20", "22"], states
    for a in ep.arrivals:
        assert abs(a.error) <= STOP_TOLERANCE, a
        assert a.stop_mark == marks[a.station].stop_mark
    # each departure: no sooner than the dwell, and as soon as both the dwell and the signal allow
    for a, d in zip(ep.arrivals, ep.departures, strict=False):
        allowed = max(a.time + marks[a.station].dwell, {"18": 100.0, "20": 330.0}[a.station])
        assert d.station == a.station
        assert allowed <= d.time <= allowed + 3.0, (a, d)
    assert [d.station for d in ep.departures] == ["18", "20"]
    seen = [s for _, s in states]
    assert seen[-1] == "finished" and {"running", "stopping", "dwelling", "held"} <= set(seen)
    assert ep.eb_count == 0


def test_a_train_held_at_a_red_starting_signal_stays_held_after_its_dwell() -> None:
    """The dwell is over but the code says stop: the train stands, held, and never departs."""
    ep, states, _, _ = run_train("1001", {}, until=250.0)
    assert [a.station for a in ep.arrivals] == ["18"]
    assert ep.departures == []
    arrived = ep.arrivals[0].time
    (dwelt, dwelling), (held, holding) = states[-2:]
    assert (dwelling, holding) == ("dwelling", "held"), states
    assert dwelt == pytest.approx(arrived, abs=0.2) and held == pytest.approx(arrived + 30, abs=0.2)


def test_a_train_enters_no_sooner_than_its_time_and_where_the_timetable_says() -> None:
    """1003 enters at TC1851 at 120 s: no cycle before (the device puts nothing on the rails),
    then its front 50 m short of the circuit's far end."""
    ep, states, run, _ = run_train("1003", {"18": 0.0}, until=200.0)
    assert run.enter_s == 120.0 and ep.first == 120.0
    assert run.config.start == 450.0 and run.config.params.length == 200.0
    assert states[0][0] == pytest.approx(120.0)
    assert ep.arrivals and ep.arrivals[0].time > 120.0
    assert abs(ep.arrivals[0].error) <= STOP_TOLERANCE


def test_a_following_train_is_held_by_the_codes_behind_the_first() -> None:
    """1001 stands at station 20 (its starting signal stays at stop); 1003, entering 120 s
    later, stops at 18 and follows: the codes behind 1001's rear circuit hold it in the
    interval, short of that circuit, without an emergency brake."""
    line = load_line()
    timetable = load_timetable(TIMETABLE, line)
    runs = {t: timetable_run(timetable.train(t), line, 0.5) for t in ("1001", "1003")}
    wayside = Wayside(line, "1", line.service_brake_mps2)
    starts = {
        18: line.station(18).signal("11").position_m,
        20: line.station(20).signal("11").position_m,
    }
    clock = VirtualClock()
    trains = {
        t: TrainEndpoint(r.config, r.line, first=max(0.1, r.enter_s)) for t, r in runs.items()
    }
    leader, follower = trains["1001"], trains["1003"]
    on = {t: False for t in trains}
    closest: list[float] = []

    def sense(me: str) -> CycleInputs:
        ep = trains[me]
        other = next(t for t in trains if t != me)
        ahead = trains[other].state.position - runs[other].config.params.length
        rears = (ahead,) if on[other] and ahead > ep.state.position else ()
        return CycleInputs(code=wayside.code(ep.state.position, rears))

    def record(me: str, now: float, out: CycleOutputs | None) -> None:
        if out is None:
            return
        on[me] = True
        wayside.signals[starts[18]] = now < 60.0
        wayside.signals[starts[20]] = True
        if on["1003"]:
            closest.append(leader.state.position - 200.0 - follower.state.position)

    for t, ep in trains.items():
        ep.sense = lambda now, t=t: sense(t)  # type: ignore[misc]
        clock.add(ep, lambda now, out, t=t: record(t, now, out))  # type: ignore[misc]
    clock.run_until(700.0)
    assert [a.station for a in leader.arrivals] == ["18", "20"]
    assert [a.station for a in follower.arrivals] == ["18"]
    assert follower.next_stop is not None and follower.next_stop.name == "20"
    assert follower.service_state(clock.now) == "held" and follower.state.speed == 0.0
    # held short of the circuit holding the leader's rear, never in it
    rear = leader.state.position - 200.0
    entry = next(
        tc.from_m for tc in line.all_track_circuits() if tc.covers(rear) and tc.on_track("1")
    )
    assert follower.state.position < entry
    assert min(closest) > 0.0
    assert leader.eb_count == 0 and follower.eb_count == 0


def test_a_train_that_leaves_the_lab_runs_to_the_end_of_the_line_and_goes_off_the_rails(
    tmp_path: Path,
) -> None:
    """`leaves_lab`: after its last stop the ATO runs on to the end of the line; standing there
    the train has left, and its process puts it beyond the line (on no track circuit)."""
    from ktcs_bench.emulator.train import TrainDevice
    from ktcs_bench.transport.endpoints import parse_endpoint

    line = load_line()
    path = tmp_path / "leaves.yaml"
    path.write_text(
        "timetable: leaves\ntrain_data:\n  seed001-table1: {length_m: 200, max_speed_kmh: 80,"
        + " traction_kmh_per_s: 3, service_brake_kmh_per_s: 3, emergency_brake_kmh_per_s: 4}\n"
        + 'trains:\n  - {id: "9", train: seed001-table1, direction: up, leaves_lab: true,\n'
        + '     depart_s: 5, stops: [{station: 22, track: "1", stop_m: 12680, dwell_s: 0}]}\n'
    )
    run = timetable_run(load_timetable(path, line).train("9"), line, 0.5)
    assert run.config.start == 12680.0 and run.config.leaves_line
    wayside = Wayside(line, "1", line.service_brake_mps2)
    ep = TrainEndpoint(run.config, run.line, first=0.1)
    ep.sense = lambda now: CycleInputs(code=wayside.code(ep.state.position))
    clock = VirtualClock()
    clock.add(ep)
    clock.run_until(4.0)
    assert ep.departures == [] and ep.service_state(clock.now) == "dwelling"
    clock.run_until(200.0)
    assert [d.station for d in ep.departures] == ["22"] and ep.departures[0].time >= 5.0
    assert ep.left and ep.service_state(clock.now) == "left"
    assert line.end_m - 5.0 < ep.state.position <= line.end_m
    device = TrainDevice("t9", line, run.config, parse_endpoint("tcp://127.0.0.1:9"), run=run)
    device.endpoint = ep
    where = device._position()
    assert where["tail"] > line.end_m and "track" not in where


# -- the operator's orders: hold, dispatch, run to -------------------------------------------------


def test_a_hold_stands_a_running_train_at_its_next_platform_past_its_departure_until_dispatch() -> (
    None
):
    """Held on the approach (an ATS platform hold): it runs on to platform 18 and stops at the
    mark, but stands there past its dwell with the signal clear, until dispatched; then it
    leaves at once."""
    ep, clock, states, _, _ = start_train("1001", {"18": 0.0})
    clock.run_until(5.0)
    assert ep.state.speed > 0.0
    assert "next platform stop, 18" in ep.hold(clock.now)
    assert ep.held and ep.commanded_stop == 1080.0
    clock.run_until(250.0)
    (arrival,) = ep.arrivals
    assert abs(arrival.error) <= STOP_TOLERANCE and arrival.time + 30.0 < 200.0
    assert ep.departures == [] and ep.service_state(clock.now) == "held"
    assert ep.held and ep.commanded_stop is None
    ep.dispatch(clock.now)
    clock.run_until(260.0)
    assert not ep.held
    assert [d.station for d in ep.departures] == ["18"]
    assert 250.0 <= ep.departures[0].time <= 252.0
    assert ep.eb_count == 0


def test_run_to_stops_the_front_within_half_a_metre_of_the_place_and_waits_for_dispatch() -> None:
    """From platform 18 to 1590 m (90 m past a tag: the tacho's 1 % alone would put it 0.9 m
    off): the ATO stops within ±0.5 m of it on the true position, stands held, leaves on
    dispatch."""
    ep, clock, _, _, _ = start_train("1001", {"18": 0.0})
    while not ep.arrivals:
        clock.run_until(clock.now + 1.0)
    assert ep.service_state(clock.now) == "dwelling"
    assert "1590" in ep.run_to(clock.now, 1590.0)  # leaves after its dwell, for 1590
    assert ep.commanded_stop == 1590.0
    clock.run_until(300.0)
    assert ep.state.speed == 0.0 and ep.service_state(clock.now) == "held"
    assert abs(ep.state.position - 1590.0) <= STOP_TOLERANCE, ep.state.position
    assert abs(ep.position.head - 1590.0) > STOP_TOLERANCE  # the raw tacho is off by its bias
    assert ep.commanded_stop is None and ep.held
    clock.run_until(330.0)
    assert abs(ep.state.position - 1590.0) <= STOP_TOLERANCE  # still there: it waits
    ep.dispatch(clock.now)
    clock.run_until(340.0)
    assert ep.state.position > 1600.0 and ep.eb_count == 0


def test_a_dispatch_on_a_stop_code_does_not_move_the_train() -> None:
    """Its dwell at 18 over, the starting signal at stop: `dispatch now` lifts nothing the ATP
    holds -- it stands at the mark; an order that cannot be carried out is refused."""
    ep, clock, _, _, _ = start_train("1001", {})
    clock.run_until(200.0)
    assert [a.station for a in ep.arrivals] == ["18"]
    head = ep.state.position
    assert "code is stop" in ep.dispatch(clock.now, at_once=True)
    clock.run_until(260.0)
    assert ep.departures == [] and ep.state.position == head and ep.state.odometer > 0.0
    assert ep.service_state(clock.now) == "held"
    with pytest.raises(UsageError, match="cannot run to 900 m"):
        ep.run_to(clock.now, 900.0)  # behind its front


def test_a_finished_train_cycles_once_a_second_and_an_order_wakes_it_at_once() -> None:
    """Its service over, standing at its last stop, the train cycles once a second (a design
    decision: nothing moves it until an order does); an order brings back the 100 ms cycle at
    once, then on the cycle's slots."""
    ep, clock, states, _, _ = start_train("1001", {"18": 100.0, "20": 330.0})
    cycles: list[float] = []
    sense = ep.sense

    def sensed(now: float) -> CycleInputs:
        cycles.append(now)
        return sense(now)

    ep.sense = sensed
    clock.run_until(900.0)
    assert states[-1][1] == "finished" and ep.at_rest
    rest = [t for t in cycles if t > states[-1][0] + 2.0]
    assert len(rest) > 10
    assert {round(b - a, 6) for a, b in zip(rest, rest[1:], strict=False)} == {1.0}
    position = ep.state.position
    now = rest[-1] + 1.25  # between its slots, after its next cycle
    clock.run_until(now)
    last = cycles[-1]
    assert last == pytest.approx(rest[-1] + 1.0)
    ep.hold(now)
    assert not ep.at_rest
    assert ep.next_deadline() <= now  # due at once
    clock.run_until(now + 1.0)
    woken = [t for t in cycles if t >= now]
    assert woken[0] == pytest.approx(now)
    assert {round(b - a, 6) for a, b in zip(woken[1:], woken[2:], strict=False)} == {0.1}
    assert woken[1] == pytest.approx(last + 0.3)  # back on its slots
    assert ep.state.position == position  # it stood throughout
