"""ARS never asks the interlocking for a route it would refuse for a reason the CTC can see.

A hypothesis state machine over the reference line in virtual time (`ars_rig`: the real IXL and
trackside cores of every station, the CTC's tables following what they indicate). Timetables are
drawn too: one to three trains, up or down, any platform track with routes in and out, any dwell,
entry time and first departure time. The rules are whatever may happen around ARS: track circuits
occupy and clear at random (trains the describer follows, and things it cannot explain), trains
step on along the line past signals or not, the operator sets and cancels any route, ARS goes on
and off per station, stations go to local mode and back, points lose detection, time jumps.

After every step, of every request ARS sent:
1. the interlocking took it (CONTROL_RESULT accepted), and the route was idle when it came --
   so ARS never asks for a route that is occupied, conflicts with one set, leads into an interval
   occupied against it, has a point without detection, or is at a station in local mode, and never
   asks for one already set;
2. it is a route the train's timetable calls for: the home route of one of its calls, or a
   starting route out of a station it calls at, in its direction;
3. it went to a station with ARS on.
KTCS_ARS_EXAMPLES raises the number of runs (default 80 of 60 steps each).
"""

from __future__ import annotations

import dataclasses
import os

from hypothesis import settings, target
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    rule,
    run_state_machine_as_test,
)

from ktcs_bench.station.model import Direction
from ktcs_bench.station.timetable import (
    Entry,
    Stop,
    Timetable,
    TimetableTrain,
    TrainData,
    home_route,
    platform_circuits,
    start_route,
)

from .ars_rig import LINE, ArsLine

STEPS = {"count": 0, "requests": 0}
TCS = [t.name for t in LINE.all_track_circuits()]
ORDER: dict[Direction, list[int]] = {
    "up": sorted(LINE.stations),
    "down": sorted(LINE.stations)[::-1],
}
ENTERS: dict[Direction, str] = {"up": "TC1851", "down": "TC2261"}


def tracks(station: int, direction: Direction, last: bool) -> list[str]:
    """Platform tracks a train in `direction` can be routed into (and, unless `last`, out of)."""
    s = LINE.station(station)
    return [
        t
        for t in s.tracks
        if home_route(s, direction, t) and (last or start_route(LINE, s, direction, t))
    ]


SEED001 = TrainData("seed001-table1", 200.0, 80.0, 3.0, 3.0, 4.0)


@st.composite
def timetables(draw: st.DrawFn) -> Timetable:
    trains = []
    for i in range(draw(st.integers(1, 3))):
        direction: Direction = draw(st.sampled_from(["up", "down"]))
        stations = ORDER[direction]
        leaves = draw(st.booleans())
        stops = []
        for k, number in enumerate(stations):
            last = k == len(stations) - 1
            track = draw(st.sampled_from(tracks(number, direction, last and not leaves)))
            s = LINE.station(number)
            home = home_route(s, direction, track)
            start = start_route(LINE, s, direction, track) if not last or leaves else None
            assert home is not None
            platform = platform_circuits(s, track)[0]
            stop_m = platform.to_m - 20 if direction == "up" else platform.from_m + 20
            stops.append(
                Stop(
                    number,
                    track,
                    stop_m,
                    draw(st.floats(0, 60)),
                    home.name,
                    start.name if start else None,
                )
            )
        standing = draw(st.booleans())  # it starts standing at its first stop, or enters
        entry = None if standing else Entry(ENTERS[direction], draw(st.floats(0, 300)))
        first = LINE.station(stops[0].station)
        appears = (
            next(
                t.name
                for t in platform_circuits(first, stops[0].track)
                if t.covers(stops[0].stop_m)
            )
            if entry is None
            else entry.track_circuit
        )
        if standing:
            stops[0] = dataclasses.replace(stops[0], home_route=None)
        trains.append(
            TimetableTrain(
                f"{1001 + 2 * i}",
                direction,
                SEED001,
                tuple(stops),
                draw(st.floats(0, 600)),
                entry,
                leaves,
                appears,
            )
        )
    return Timetable("drawn", "<hypothesis>", tuple(trains))


class ArsMachine(RuleBasedStateMachine):
    @initialize(
        timetable=timetables(),
        on=st.just(set(LINE.stations)) | st.sets(st.sampled_from(sorted(LINE.stations))),
    )
    def start(self, timetable: Timetable, on: set[int]) -> None:
        self.b = ArsLine(on=on, timetable=timetable)
        self.timetable = timetable
        self.checked = 0

    # -- the railway --------------------------------------------------------------------------
    @rule(tc=st.sampled_from(TCS), occupied=st.booleans())
    def occupancy(self, tc: str, occupied: bool) -> None:
        self.b.occupy(tc, occupied=occupied)

    @rule(data=st.data(), steps=st.integers(1, 20), dt=st.sampled_from([0.0, 2.0, 5.0]))
    def trains_step_on(self, data: st.DataObject, steps: int, dt: float) -> None:
        """Trains step on as trains do: one holding two circuits clears its rear, else its head
        steps into a circuit ahead (mostly along a set route, past a signal at stop or not); or
        the next train of the timetable comes onto the line where it enters. `dt` seconds
        pass before each step."""
        describer = self.b.ars.describer
        for _ in range(steps):
            self.b.advance(dt)
            trains = [t for t in describer.trains.values() if not t.lost]
            if describer.expected and (not trains or data.draw(st.integers(0, 9)) == 0):
                self.b.occupy(describer.expected[0].appears_on)
                continue
            if not trains:
                return
            t = data.draw(st.sampled_from(trains))
            if len(t.footprint) > 1:
                self.b.clear(t.footprint[0])
                continue
            ahead = sorted(describer.ahead(t.berth, t.direction))
            routed = [tc for tc in ahead if tc in self.routed()]
            mostly = data.draw(st.integers(0, 4)) > 0  # mostly the way a set route leads
            if routed and mostly:
                ahead = routed
            if ahead:
                self.b.occupy(data.draw(st.sampled_from(ahead)))

    def routed(self) -> set[str]:
        """The track circuits of the routes the interlockings hold set."""
        return {
            tc
            for number, rig in self.b.rigs.items()
            for r in LINE.station(number).routes
            if rig.ixl.route_status(r.name).value != "idle"
            for tc in r.track_circuits
        }

    @rule(seconds=st.floats(0.1, 120.0))
    def time_passes(self, seconds: float) -> None:
        self.b.advance(seconds)

    @rule(data=st.data(), fail=st.booleans())
    def point_detection(self, data: st.DataObject, fail: bool) -> None:
        station = data.draw(st.sampled_from(sorted(LINE.stations)))
        rig = self.b.rig(station)
        if fail:
            point = data.draw(st.sampled_from([p.name for p in LINE.station(station).points]))
            rig.from_field(rig.io.fail_point(point, "detection", rig.now).changes)
        else:
            rig.from_field(rig.io.clear_faults(rig.now).changes)
        self.b.update()

    # -- the operator -------------------------------------------------------------------------
    @rule(data=st.data(), cancel=st.booleans())
    def operator_route(self, data: st.DataObject, cancel: bool) -> None:
        station = data.draw(st.sampled_from(sorted(LINE.stations)))
        route = data.draw(st.sampled_from(LINE.station(station).routes))
        model = self.b.model.station(station)
        if cancel:
            action = model.cancel_route(route.entry, self.b.model.state(station), route.exit)
        else:
            action = model.set_route(route.entry, route.exit)
        self.b.operator(station, action.name)

    @rule(data=st.data())
    def operator_sets_a_conflicting_route(self, data: st.DataObject) -> None:
        """The operator sets a route in the way of one a train waits for (a route by hand
        against ARS, as when the operator moves another train)."""
        wanted = [p.wanted for p in self.b.ars.progress.values() if p.wanted is not None]
        if not wanted:
            return
        station, name = data.draw(st.sampled_from(sorted(wanted)))
        conflicts = LINE.station(station).route(name).conflicts
        other = LINE.station(station).route(data.draw(st.sampled_from(conflicts)))
        self.b.operator(
            station, self.b.model.station(station).set_route(other.entry, other.exit).name
        )

    @rule(station=st.sampled_from(sorted(LINE.stations)), on=st.booleans())
    def ars_switch(self, station: int, on: bool) -> None:
        self.b.ars.switch(station, on, self.b.now)
        self.b.update()

    @rule(station=st.sampled_from(sorted(LINE.stations)), local=st.booleans())
    def mode(self, station: int, local: bool) -> None:
        rig = self.b.rig(station)
        if local:
            rig.take(rig.ixl.local("take", rig.now))
        else:
            rig.control(self.b.model.station(station).mode("center").name)
            rig.take(rig.ixl.local("grant", rig.now))
        self.b.update()

    # -- what must hold -----------------------------------------------------------------------
    @invariant()
    def every_request_was_one_the_interlocking_took(self) -> None:
        STEPS["count"] += 1
        for s in self.b.sent[self.checked :]:
            STEPS["requests"] += 1
            req = s.request
            assert s.result.accepted, f"{req} refused: {s.result.reason.text}\n{self.log()}"
            assert s.before.value == "idle", f"{req} asked while {s.before.value}\n{self.log()}"
            train = self.timetable.train(req.train)
            homes = {(c.station, c.home_route) for c in train.stops if c.home_route}
            starts = {
                (c.station, r.name)
                for c in train.stops
                for track in LINE.station(c.station).tracks
                if (r := start_route(LINE, LINE.station(c.station), train.direction, track))
            }
            assert (req.station, req.route) in homes | starts, f"{req} not in the timetable"
            assert s.ars_on, f"{req} sent with ARS off at station {req.station}"
        self.checked = len(self.b.sent)

    def teardown(self) -> None:
        if hasattr(self, "b"):
            target(float(len(self.b.sent)), label="requests ARS sent")  # towards busy runs

    def log(self) -> str:
        return self.b.log_text()


def test_ars_never_asks_for_a_route_the_interlocking_would_refuse() -> None:
    STEPS.update(count=0, requests=0)
    examples = int(os.environ.get("KTCS_ARS_EXAMPLES", "80"))
    run_state_machine_as_test(
        ArsMachine, settings=settings(max_examples=examples, stateful_step_count=60, deadline=None)
    )
    assert STEPS["count"] >= 2_000, STEPS["count"]
    assert STEPS["requests"] >= 20, STEPS  # ARS was busy: the property was not checked on nothing
