"""Losing the rails is fail-safe (SPEC §6.2 invariant 3, §6.4), as a hypothesis state machine.

One station's sans-I/O cores wired as the lab wires them -- the IXL takes track occupancy from its
ATC (`tc_sources=("atc",)`), points and lamps from its trackside I/O -- over perfect links that
the machine may drop and restore (a restored link exchanges full states, as REQUEST_ALL/ALL_INFO
do). It starts with the rails up and a route set whose signal clears (so the harness can clear a
signal at all), then the rails are lost on the ATC and the trackside. From then on any sequence of
commands and field events comes: route set/cancel, point moves, stop holds, mode changes,
occupancy reports (from a source that is gone), relay and point faults, link losses, time. After
every step no signal shows proceed, the ATC reports every track circuit occupied and gives every
track circuit the most restrictive code.
"""

from __future__ import annotations

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    rule,
    run_state_machine_as_test,
)

from ktcs_bench.atc import WaysideAtc
from ktcs_bench.atc.wayside import AtcOutput
from ktcs_bench.field import Trackside
from ktcs_bench.field.trackside import FieldOutput
from ktcs_bench.ixl import Interlocking, Mode
from ktcs_bench.ixl.interlocking import IxlOutput
from ktcs_bench.station import load_line
from ktcs_bench.station.model import Route
from ktcs_bench.station_codes import names as n

LINE = load_line()
ALL_TCS = [t.name for t in LINE.all_track_circuits()]


class RailsLostMachine(RuleBasedStateMachine):
    @initialize(station=st.sampled_from(sorted(LINE.stations)), data=st.data())
    def start(self, station: int, data: st.DataObject) -> None:
        self.view = view = LINE.view(station)
        self.st = station
        self.now = 0.0
        self.ixl = Interlocking(view, mode=Mode.CENTER, tc_sources=("atc",))
        self.io = Trackside(view)
        self.atc = WaysideAtc(LINE, station)
        self.links = {"atc": False, "io": False}
        self.routes = [r.name for r in view.station.routes]
        self.points = [p.name for p in view.station.points]
        self.signals = [s.name for s in view.station.lamp_signals]
        self.tcs = [t.name for t in view.track_circuits]
        for link in ("atc", "io"):
            self.set_link(link, True)
        self.from_io(self.io.set_occupancy(dict.fromkeys(ALL_TCS, False), self.now))
        self.from_atc(self.atc.set_occupancy(dict.fromkeys(ALL_TCS, False), self.now))
        # with the rails up a route is set and its signal clears: the harness can clear signals
        # (a lone station departs only into intervals it holds: SPEC §6.6, no neighbour to ask)
        settable = [r for r in self.routes if self._may_depart(view.station.route(r))]
        route = view.station.route(data.draw(st.sampled_from(settable)))
        self.from_ixl(self.ixl.control(n.rsc(station, route.name), 1, self.now))
        self.advance(10.0)
        assert self.ixl.aspect(route.entry) != "R", f"route {route.name} did not clear"
        # the rails are lost: the track-circuit emulator is gone
        self.from_atc(self.atc.rails_state(False, self.now))
        self.from_io(self.io.rails_state(False, self.now))
        assert self.ixl.aspect(route.entry) == "R"

    def _may_depart(self, route: Route) -> bool:
        iv = self.view.interval_of_exit(route)
        return iv is None or iv.boundary or self.ixl.ends[iv.name].holds

    # ---------------------------------------------------------------- wiring (perfect links)

    def from_ixl(self, out: IxlOutput) -> None:
        if out.of("atc") and self.links["atc"]:
            self.from_atc(self.atc.receive(dict(out.of("atc")), self.now))
        if out.of("io") and self.links["io"]:
            self.from_io(self.io.receive(dict(out.of("io")), self.now))

    def from_atc(self, out: AtcOutput) -> None:
        if out.ixl and self.links["atc"]:
            self.from_ixl(self.ixl.receive("atc", dict(out.ixl), self.now))

    def from_io(self, out: FieldOutput) -> None:
        if out.changes and self.links["io"]:
            self.from_ixl(self.ixl.receive("io", dict(out.changes), self.now))

    def set_link(self, link: str, up: bool) -> None:
        self.links[link] = up
        peer = self.atc if link == "atc" else self.io
        self.from_ixl(self.ixl.link_state(link, up, self.now))
        if link == "atc":
            self.from_atc(self.atc.link_state(up, self.now))
        else:
            self.from_io(self.io.link_state(up, self.now))
        if up:  # both ends rebuild the other's view from a full state
            self.from_ixl(self.ixl.receive(link, peer.full_state(), self.now))
            full = self.ixl.full_state(link)
            if link == "atc":
                self.from_atc(self.atc.receive(full, self.now))
            else:
                self.from_io(self.io.receive(full, self.now))

    def advance(self, seconds: float) -> None:
        end = self.now + seconds
        while True:
            # a deadline not after `now` was seen by the last call: only later ones move time on
            due = [self.ixl.next_deadline(), self.io.next_deadline()]
            nxt = min((d for d in due if d is not None and d > self.now), default=None)
            if nxt is None or nxt > end:
                break
            self.now = max(self.now, nxt)
            self.from_io(self.io.handle_timer(self.now))
            self.from_ixl(self.ixl.handle_timer(self.now))
        self.now = end
        self.from_io(self.io.handle_timer(self.now))
        self.from_ixl(self.ixl.handle_timer(self.now))

    # ---------------------------------------------------------------- rules: commands

    @rule(data=st.data(), cancel=st.booleans())
    def route_control(self, data: st.DataObject, cancel: bool) -> None:
        route = data.draw(st.sampled_from(self.routes))
        code = n.rcc(self.st, route) if cancel else n.rsc(self.st, route)
        self.from_ixl(self.ixl.control(code, 1, self.now))

    @rule(data=st.data())
    def set_route_and_wait(self, data: st.DataObject) -> None:
        """The case of the defect: a route set after the rails went, points given time."""
        route = data.draw(st.sampled_from(self.routes))
        self.from_ixl(self.ixl.control(n.rsc(self.st, route), 1, self.now))
        self.advance(10.0)

    @rule(data=st.data(), reverse=st.booleans())
    def point_control(self, data: st.DataObject, reverse: bool) -> None:
        point = data.draw(st.sampled_from(self.points))
        code = n.src(self.st, point) if reverse else n.snc(self.st, point)
        self.from_ixl(self.ixl.control(code, 1, self.now))

    @rule(data=st.data(), hold=st.booleans())
    def signal_stop(self, data: st.DataObject, hold: bool) -> None:
        signal = data.draw(st.sampled_from(self.signals))
        self.from_ixl(self.ixl.control(n.ssc(self.st, signal), int(hold), self.now))

    @rule(action=st.sampled_from(["CMQ", "LMQ", "grant", "take"]))
    def mode(self, action: str) -> None:
        if action in ("CMQ", "LMQ"):
            self.from_ixl(self.ixl.control(f"{action}{self.st}", 1, self.now))
        else:
            self.from_ixl(self.ixl.local(action, self.now))

    # ---------------------------------------------------------------- rules: the field

    @rule(report=st.dictionaries(st.sampled_from(ALL_TCS), st.booleans(), min_size=1))
    def occupancy_report(self, report: dict[str, bool]) -> None:
        """Reports as if from the rails, which are gone (a stale or stray message)."""
        self.from_atc(self.atc.set_occupancy(report, self.now))
        self.from_io(self.io.set_occupancy(report, self.now))

    @rule()
    def everything_clear_reported(self) -> None:
        clear = dict.fromkeys(ALL_TCS, False)
        self.from_atc(self.atc.set_occupancy(clear, self.now))
        self.from_io(self.io.set_occupancy(clear, self.now))

    @rule(up=st.booleans())
    def trackside_rails(self, up: bool) -> None:
        """The trackside's rails may come back: it is not the IXL's source of occupancy."""
        self.from_io(self.io.rails_state(up, self.now))

    @rule(data=st.data(), kind=st.sampled_from(["failed_clear", "failed_occupied"]))
    def relay_fault(self, data: st.DataObject, kind: str) -> None:
        tc = data.draw(st.sampled_from(self.tcs))
        self.from_io(self.io.fail_track_circuit(tc, kind, self.now))

    @rule(data=st.data(), kind=st.sampled_from(["detection", "jammed"]))
    def point_fault(self, data: st.DataObject, kind: str) -> None:
        self.from_io(self.io.fail_point(data.draw(st.sampled_from(self.points)), kind, self.now))

    @rule()
    def faults_cleared(self) -> None:
        self.from_io(self.io.clear_faults(self.now))

    @rule(link=st.sampled_from(["atc", "io"]), up=st.booleans())
    def link(self, link: str, up: bool) -> None:
        self.set_link(link, up)

    @rule(seconds=st.sampled_from([0.5, 5.0, 31.0, 61.0, 100.0]))
    def time_passes(self, seconds: float) -> None:
        self.advance(seconds)

    # ---------------------------------------------------------------- invariants

    @invariant()
    def no_signal_clears(self) -> None:
        atc_codes = self.ixl.full_state("atc")
        for s in self.signals:
            assert self.ixl.aspect(s) == "R", f"signal {s} shows {self.ixl.aspect(s)}"
            assert atc_codes[n.sgp(self.st, s)] == 0
            assert self.io.signals[s].lit() in ("R", None), f"signal {s} lit proceed"

    @invariant()
    def the_atc_reports_everything_occupied_and_gives_stop_codes(self) -> None:
        assert all(v == 1 for v in self.atc.full_state().values())
        stop = LINE.most_restrictive_code
        for code in self.atc.track_codes().values():
            assert (code.code, code.target_speed_kmh, code.target_distance_m) == (stop.code, 0, 0)
        assert all(self.ixl.occupied(t) for t in self.tcs)


def test_with_the_rails_lost_no_signal_clears_whatever_commands_come() -> None:
    run_state_machine_as_test(
        RailsLostMachine, settings=settings(max_examples=150, stateful_step_count=40)
    )
