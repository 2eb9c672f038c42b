"""One station's wayside ATC (SPEC §6.4), sans-I/O.

Reads track occupancy (from the track-circuit model, any track circuit of the line), reads the
route state from its IXL (IXL->ATC chart: routes set, points, signals at proceed, traffic
direction), reports TC/TTC/IZC codes to the IXL (ATC->IXL chart), and gives each of its track
circuits a code: target speed from the line's code table, gradient, and the distance to the next
stop point — the end of the set route (a signal at stop) or the rear of the next occupied track
circuit. While its Type I link to the IXL is in communication error every track circuit gets the
most restrictive code.

Occupancy comes from the rails (the track-circuit emulator). When the rails are lost
(`rails_state(False)`) the ATC knows nothing of where trains are: every track circuit is occupied
in what it reports to the IXL and in its own codes (all the most restrictive), reports that still
come are ignored, and after `rails_state(True)` each track circuit stays occupied until the rails
report it again (SPEC §6.2 invariant 3, §6.4).

The ATC has no timer, so it has no `next_deadline`/`handle_timer` (the timer shape of
`ktcs_bench.timed`): every code follows at once from its inputs -- occupancy, the IXL's codes, the
link and the rails -- and nothing in it changes while they stand still. What is time-driven around
it lives in its links and reaches it as an input: the Type I link's communication error
(`link_state`), the loss of the rails connection (`rails_state`).

How the path ahead of a track circuit is found, in order: a set route through it; a set route
from the signal it approaches, if that signal shows proceed; the route that last held it (so a
train keeps its path after the entry signal went back to stop); on the plain line, the traffic
direction. Beyond this station's own signals nothing is known, so a path leaving the station ends
at the far end of the interval (the next station's home signal) as a stop point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ktcs_bench.atc.track_codes import (
    AtcCode,
    braking_decel,
    braking_speed_kmh,
    most_restrictive,
    quantise,
)
from ktcs_bench.station.model import Direction, Interval, Line, Route, TrackCircuit
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.names import Function as F
from ktcs_bench.station_codes.stations import StationCodes

MAX_ROUTES_AHEAD = 4  # a path never chains more routes than a station has in a row


@dataclass(frozen=True, slots=True)
class AtcEvent:
    time: float
    kind: str
    text: str


@dataclass
class AtcOutput:
    ixl: list[tuple[str, int]] = field(default_factory=list)  # ATC->IXL code changes
    codes: dict[str, AtcCode] = field(default_factory=dict)  # track-circuit codes that changed
    events: list[AtcEvent] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class _Path:
    direction: Direction
    ahead: tuple[str, ...]  # track circuits after this one, in running order, up to the stop
    limit_kmh: float | None  # route speed limit over this track circuit, if any


class WaysideAtc:
    def __init__(self, line: Line, station: int) -> None:
        self.line = line
        self.view = line.view(station)
        self.st = station
        self.own: tuple[TrackCircuit, ...] = self.view.track_circuits
        self.tc: dict[str, TrackCircuit] = {t.name: t for t in line.all_track_circuits()}
        self.occupied: dict[str, bool] = {}  # unknown = occupied
        self.ixl: dict[str, int] = {}  # last IXL->ATC code states; unknown = 0
        self.link_up = False
        self.rails_up = True  # the occupancy source is there (an adapter with rails says when not)
        self.tc_route: dict[str, str] = {}  # track circuit -> route that last held it
        self.codes = StationCodes(self.view)
        self._inputs = self.codes.names("ixl_to_atc")
        self._routes = self.view.station.routes
        # for grading the code steps, fixed with the line: each circuit's gradient in a running
        # direction, line limit, and the routes with a speed limit of their own over it
        self._slopes: dict[tuple[str, Direction], float] = {}
        self._line_limits: dict[str, float] = {}
        self._limited: dict[str, list[Route]] = {}
        for r in self._routes:
            for name in r.track_circuits if r.speed_limit_kmh is not None else ():
                self._limited.setdefault(name, []).append(r)
        self.log: list[AtcEvent] = []
        self._events: list[AtcEvent] = []
        self._sent = self.full_state()
        self._codes = self.track_codes()

    # ------------------------------------------------------------------ inputs

    def set_occupancy(self, occupied: Mapping[str, bool], now: float) -> AtcOutput:
        """Occupancy of any track circuits of the line (changes or all); ignored while the rails
        are lost."""
        if self.rails_up:
            self.occupied.update({k: bool(v) for k, v in occupied.items()})
        return self._finish(now)

    def rails_state(self, up: bool, now: float) -> AtcOutput:
        """The rails (the source of occupancy) lost or back. Lost: every track circuit occupied
        until reported again, the most restrictive code everywhere."""
        if up != self.rails_up:
            self.rails_up = up
            if up:
                self._event(now, "rails", "rails back: occupancy as the rails report it")
            else:
                self.occupied.clear()  # unknown = occupied
                self._event(
                    now, "rails", "rails lost: every track circuit occupied, most restrictive code"
                )
        return self._finish(now)

    def receive(self, codes: Mapping[str, int], now: float) -> AtcOutput:
        """IXL->ATC code changes or a full state."""
        for name, state in codes.items():
            if name not in self._inputs:
                self._event(now, "fault", f"unknown code {name!r} from the IXL ignored")
                continue
            before = self.ixl.get(name, 0)
            self.ixl[name] = int(state)
            code = self.codes.parse_code(name)
            if code is not None and code.function is F.RLI and state and not before:
                route = self.view.station.route(code.object)
                for t in route.track_circuits:
                    self.tc_route[t] = route.name
        return self._finish(now)

    def link_state(self, up: bool, now: float) -> AtcOutput:
        if up != self.link_up:
            self.link_up = up
            what = "up" if up else "in communication error: most restrictive code everywhere"
            self._event(now, "link", f"IXL link {what}")
        return self._finish(now)

    # ------------------------------------------------------------------ queries

    def input_names(self) -> tuple[str, ...]:
        return self._inputs

    def full_state(self) -> dict[str, int]:
        """Every ATC->IXL chart code: TC, TTC, IZC (1 occupied)."""
        out = {t.name: int(self._occ(t.name)) for t in self.own}
        for ttc in self.codes.totalisers:
            out[ttc.name] = int(any(self._occ(t) for t in ttc.track_circuits))
        for iv in self.view.intervals:
            out[n.izc(iv.name)] = int(any(self._occ(t) for t in iv.track_circuits))
        return out

    def track_codes(self) -> dict[str, AtcCode]:
        """The code of every track circuit this ATC drives."""
        out: dict[str, AtcCode] = {}
        for t in self.own:
            if not (self.link_up and self.rails_up):
                out[t.name] = most_restrictive(self.line, self._gradient(t, "up"))
                continue
            path = self._path(t)
            if path is None:
                out[t.name] = most_restrictive(self.line, self._gradient(t, "up"))
            else:
                out[t.name] = self._code(t, path)
        return out

    # ------------------------------------------------------------------ code computation

    def _occ(self, tc: str) -> bool:
        return not self.rails_up or self.occupied.get(tc, True)

    def _on(self, name: str) -> bool:
        return self.ixl.get(name, 0) == 1

    def _set(self, route: Route) -> bool:
        return self._on(n.rli(self.st, route.name))

    def _proceed(self, signal: str) -> bool:
        return self._on(n.sgp(self.st, signal))

    def _set_route_from(self, signal: str) -> Route | None:
        for r in self._routes:
            if r.entry == signal and self._set(r):
                return r
        return None

    def _path(self, t: TrackCircuit) -> _Path | None:
        name = t.name
        through = [r for r in self._routes if self._set(r) and name in r.track_circuits]
        if through:
            r = next((x for x in through if self._proceed(x.entry)), through[0])
            return self._along(r, name)
        for r in self._routes:
            if name in r.approach[-1:] and self._proceed(r.entry) and self._set(r):
                return _Path(r.direction, r.track_circuits + self._beyond(r, 0), None)
        last = self.tc_route.get(name)
        if last is not None:
            return self._along(self.view.station.route(last), name)
        for iv in self.view.intervals:
            if name in iv.track_circuits:
                return self._interval_path(iv, name)
        return None

    def _along(self, r: Route, name: str) -> _Path:
        i = r.track_circuits.index(name)
        return _Path(r.direction, r.track_circuits[i + 1 :] + self._beyond(r, 0), r.speed_limit_kmh)

    def _beyond(self, r: Route, depth: int) -> tuple[str, ...]:
        """Track circuits past route `r`'s exit that a train may run onto (up to a stop)."""
        iv = self.view.interval_of_exit(r)
        if iv is not None:
            tcs = iv.track_circuits if r.direction == "up" else tuple(reversed(iv.track_circuits))
            return tcs
        if depth >= MAX_ROUTES_AHEAD or not self._proceed(r.exit):
            return ()
        nxt = self._set_route_from(r.exit)
        if nxt is None:
            return ()
        return nxt.track_circuits + self._beyond(nxt, depth + 1)

    def _interval_path(self, iv: Interval, name: str) -> _Path | None:
        up, down = self._on(n.tdu(iv.name)), self._on(n.tdd(iv.name))
        if up == down:
            return None  # direction unknown: stop
        direction: Direction = "up" if up else "down"
        order = iv.track_circuits if up else tuple(reversed(iv.track_circuits))
        ahead = order[order.index(name) + 1 :]
        if iv.toward(self.st) == direction:
            home = next(
                (
                    s
                    for s in self.view.station.lamp_signals
                    if s.kind == "home" and s.direction == direction
                ),
                None,
            )
            if home is not None and self._proceed(home.name):
                r = self._set_route_from(home.name)
                if r is not None:
                    ahead += r.track_circuits + self._beyond(r, 0)
        return _Path(direction, ahead, None)

    def _route_limit(self, tc: str) -> float | None:
        """The lowest limit of a set route over track circuit `tc` (a diverging route's own
        speed), None when no set route over it has one."""
        limits = [
            r.speed_limit_kmh
            for r in self._limited.get(tc, ())
            if r.speed_limit_kmh is not None and self._set(r)
        ]
        return min(limits, default=None)

    def _limit(self, t: TrackCircuit, route_limit: float | None) -> float:
        limit = self.line.speed_limit_between(t.from_m, t.to_m)
        return min(limit, route_limit) if route_limit is not None else limit

    def _gradient(self, t: TrackCircuit, direction: Direction) -> float:
        if direction == "up":
            return self.line.gradient_between(t.from_m, t.to_m)
        return -self.line.highest_gradient_between(t.from_m, t.to_m)

    def _code(self, t: TrackCircuit, path: _Path) -> AtcCode:
        """The code of `t`: the speed at its exit from the graded steps to the stop point.

        Backwards from the stop (0 at the exit of the last free track circuit), each free track
        circuit's entry speed is what braking over it allows down to its exit speed
        (`braking_speed_kmh` on `braking_decel` of the most adverse gradient from `t` to the
        stop, after the line's brake build-up time), no more than its own limit and the next
        one's, quantised to the code table: so the speed at `t`'s exit is one from which every
        code step ahead can be braked for. The steps it counts on are never above the codes the
        circuits ahead get themselves: their own grading sees the same limits and the same or a
        milder gradient."""
        free: list[TrackCircuit] = []
        for name in path.ahead:
            if self._occ(name):
                break
            free.append(self.tc[name])
        distance = t.length_m + sum(x.length_m for x in free)  # from t's entry to the stop
        gradient = self._slope(t, path.direction)
        if not free:  # the stop is at this circuit's exit
            code, kmh = quantise(self.line, 0.0)
            return AtcCode(code, kmh, gradient, distance, path.direction)
        adverse = min([gradient, *(self._slope(x, path.direction) for x in free)])
        decel = braking_decel(self.line, adverse)
        build_up = self.line.brake_build_up_s
        limits = [self._limit(t, path.limit_kmh), *(self._limit_over(x.name) for x in free)]
        exit_kmh = 0.0  # at the exit of the last free circuit: the stop
        for i in range(len(free) - 1, -1, -1):  # free[i]'s entry = the exit of the one before
            entry = braking_speed_kmh(free[i].length_m, decel, build_up, exit_kmh)
            exit_kmh = quantise(self.line, min(limits[i], limits[i + 1], entry))[1]
        code, kmh = quantise(self.line, exit_kmh)
        return AtcCode(code, kmh, gradient, distance, path.direction)

    def _slope(self, t: TrackCircuit, direction: Direction) -> float:
        """`_gradient`, kept: the line does not change."""
        key = (t.name, direction)
        g = self._slopes.get(key)
        if g is None:
            g = self._slopes[key] = self._gradient(t, direction)
        return g

    def _limit_over(self, tc: str) -> float:
        """The lowest limit over track circuit `tc` as its own code takes it: the line's, a set
        route's over it, the route that last held it (so a step graded to it is never above the
        code it gets itself)."""
        limit = self._line_limits.get(tc)
        if limit is None:
            t = self.tc[tc]
            limit = self._line_limits[tc] = self.line.speed_limit_between(t.from_m, t.to_m)
        route = self._route_limit(tc)
        if route is not None:
            limit = min(limit, route)
        last = self.tc_route.get(tc)
        if last is not None:
            held = self.view.station.route(last).speed_limit_kmh
            if held is not None:
                limit = min(limit, held)
        return limit

    # ------------------------------------------------------------------ outputs

    def _finish(self, now: float) -> AtcOutput:
        state = self.full_state()
        codes = self.track_codes()
        out = AtcOutput(
            ixl=[(k, v) for k, v in state.items() if self._sent.get(k) != v],
            codes={k: v for k, v in codes.items() if self._codes.get(k) != v},
            events=self._events,
        )
        self._sent, self._codes, self._events = state, codes, []
        return out

    def _event(self, now: float, kind: str, text: str) -> None:
        ev = AtcEvent(now, kind, text)
        self._events.append(ev)
        self.log.append(ev)
