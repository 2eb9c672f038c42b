"""Automatic route setting (ARS): the CTC sets each train's routes from the timetable (pure).

As a real CTC's ARS does, it follows every train (the describer, `ctc.describer`, gives trains
their numbers from occupancy) and asks for the next route of its timetable when the train is
ready for it:

* the **home route** into the stop's platform track when the train approaches the station's
  home signal: its head is on the route's approach track circuits or on the plain line the
  station owns before that signal;
* the **starting route** out of the platform when the train has stood there for its dwell (from
  the moment it stands wholly on the platform's track circuit). A train that stopped on another
  track than the timetable's leaves from the track it is on.

A train's first route is not asked for before its `enters.at_s`, nor its first departure before
its `depart_s` (the timetable's times: seconds from the CTC's start). A route is asked for only when
everything the CTC can see says the interlocking will take it: ARS is on at the station, the
station's indications are known and it is in center mode, the route is not set already, no
conflicting route is set (or asked for), none of its track circuits (overlap included) is
occupied, none of its points has lost detection or is locked the other way, and the interval it
leads into is not occupied against its direction. Otherwise the train **waits** and the reason
goes to the log once, when it changes. Of two trains wanting the same signal, the one nearer asks.

A station showing every one of its track circuits occupied shows its interlocking's fail-safe
picture (its ATC link down, or up and not yet reporting): ARS reads that as occupancy not known,
not as trains -- it steps, clears and identifies no train, and sets no route over it.

Inputs: `update(now)` after the CTC's indication tables changed (it reads them through the
`CtcModel`), `handle_timer(now)` at `next_deadline()` (a dwell ending, a train becoming due, a
retry), `switch(station, on, now)` and `result(request, accepted, why, now)` with what came of a
request. `update` and `handle_timer` return the `RouteRequest`s to send, in the CTC desk's words
(`request.command`). A rejected or unanswered request is asked again after `RETRY_S`; an accepted
one not again for that train unless its route drops before the train has entered it (an operator
cancelled it). Every log entry is also handed to `on_log` (the CTC device puts it in its events).
No clock, no I/O.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypedDict

from ktcs_bench import kinds, messages
from ktcs_bench.ctc.describer import DescribedTrain, Describer
from ktcs_bench.ctc.model import CtcModel, StationReading
from ktcs_bench.station.model import Route, Station
from ktcs_bench.station.timetable import Stop, Timetable, TimetableTrain, start_route

RETRY_S = 5.0  # a rejected or unanswered request: ask again no sooner
GRANT_GRACE_S = 10.0  # an accepted request whose route is not indicated set by then: ask again
LOG_KEEP = 2_000  # log entries kept
FAIL_SAFE_MIN = 3  # a station with this many circuits or more, all occupied: its fail-safe picture


class ArsLogEntry(TypedDict):
    """One entry of ARS's log: what it asked for, what came of it, why a train waits."""

    time: float  # ARS's time (s from the CTC's start)
    station: int | None
    train: str | None
    text: str


@dataclass(frozen=True, slots=True)
class RouteRequest:
    """One route ARS asks the interlocking for, for one train."""

    train: str
    station: int
    route: str
    entry: str
    exit: str

    @property
    def command(self) -> messages.Route:
        """The request as the CTC desk takes it (`CtcModel.action`)."""
        return messages.Route(action="set", station=self.station, entry=self.entry, exit=self.exit)

    @property
    def text(self) -> str:
        return f"route {self.entry}-{self.exit} at station {self.station}"


@dataclass
class _Grant:
    at: float
    seen: bool = False  # the route has been indicated set since


@dataclass(frozen=True, slots=True)
class _Want:
    """What a train needs next: `route` at `station` (None: nothing now), and why it waits for
    it (None: it may be asked for if the interlocking will take it; "": not yet, nothing worth
    logging -- the train is not yet where the route is asked for)."""

    station: int | None
    route: Route | None
    why: str | None


@dataclass
class _Progress:
    """Where a train is in its timetable."""

    stop: int = 0  # index of the stop it runs to (or stands at)
    phase: str = "approach"  # approach | arriving | dwell | terminated | leaving
    arrived_at: float | None = None
    track: str | None = None  # the platform track it stands on
    waiting: str | None = None  # why it waits now (logged when it changes)
    wanted: tuple[int, str] | None = None  # (station, route) it wants next


class Ars:
    """Automatic route setting for one CTC. See the module docstring."""

    def __init__(
        self, model: CtcModel, timetable: Timetable, on: Iterable[int] = (), keep: int = LOG_KEEP
    ) -> None:
        self.model = model
        self.line = model.line
        self.timetable = timetable
        self.enabled: dict[int, bool] = dict.fromkeys(model.models, False)
        for st in on:
            self.enabled[self.model.station(st).number] = True
        self.describer = Describer(self.line, timetable)
        self.progress: dict[str, _Progress] = {}
        self.log: deque[ArsLogEntry] = deque(maxlen=keep)
        self.on_log: Callable[[ArsLogEntry], None] | None = None  # told of each entry
        self.pending: dict[tuple[int, str], RouteRequest] = {}  # sent, no result yet
        self.granted: dict[tuple[str, int, str], _Grant] = {}  # (train, station, route)
        self.retry_at: dict[tuple[str, int, str], tuple[float, str]] = {}  # -> (when, why)
        self.requests_made = 0
        self._now = 0.0
        self._station_tcs = {
            st: {t.name for t in self.line.station(st).track_circuits} for st in model.models
        }

    # ------------------------------------------------------------------ inputs

    def switch(self, station: object, on: bool, now: float) -> None:
        """ARS on or off at `station` (a number or its digits; UsageError if not served)."""
        st = self.model.station(station).number
        if self.enabled.get(st) != on:
            self.enabled[st] = on
            self._log(now, f"ARS {'on' if on else 'off'} at station {st}", station=st)

    def update(self, now: float) -> list[RouteRequest]:
        """The indication tables changed (or time passed): follow the trains, ask for routes."""
        self._now = max(self._now, now)
        readings = self._readings()
        occupancy: dict[str, bool | None] = {}
        for reading in readings.values():
            occupancy.update(self._occupancy(reading))
        for e in self.describer.update(occupancy, now):
            self._log(now, e.text, train=e.train)
        for train_id in list(self.progress):
            if train_id not in self.describer.trains:
                del self.progress[train_id]
        self._drop_stale_grants(readings, now)
        requests: list[RouteRequest] = []
        claimed: dict[tuple[int, str], str] = {}  # (station, entry signal) -> the leading train
        for t in self.describer._order():
            p = self.progress.setdefault(t.id, self._start(t))
            self._advance(t, p, now)
            want = self._wanted(t, p, now)
            station, route = want.station, want.route
            p.wanted = (station, route.name) if station is not None and route else None
            if station is None or route is None or want.why is not None:
                self._wait(t, p, want.why or None, now)
                continue
            key = (station, route.entry)
            if key in claimed:
                self._wait(t, p, f"behind train {claimed[key]}", now)
                continue
            claimed[key] = t.id
            why = self._check(t, station, route, readings, occupancy, now)
            if why is not None:
                self._wait(t, p, why or None, now)
                continue
            req = RouteRequest(t.id, station, route.name, route.entry, route.exit)
            self.pending[(station, route.name)] = req
            self.requests_made += 1
            p.waiting = None
            self._log(now, f"train {t.id}: requests {req.text}", station=station, train=t.id)
            requests.append(req)
        return requests

    def _readings(self) -> dict[int, StationReading]:
        """Each station whose indications the CTC knows, read (again only if its table moved)."""
        return {st: r for st in self.model.models if (r := self.model.reading(st)) is not None}

    @staticmethod
    def _occupancy(reading: StationReading) -> dict[str, bool | None]:
        """A station's occupancy as ARS takes it. Every circuit of a station occupied at once is
        its interlocking's fail-safe picture (its ATC link down, or up and not yet reporting):
        not known, not trains. A station with fewer than `FAIL_SAFE_MIN` circuits is taken as
        read."""
        tcs = reading.track_circuits
        if len(tcs) >= FAIL_SAFE_MIN and all(v is True for v in tcs.values()):
            return dict.fromkeys(tcs, None)
        return tcs

    def handle_timer(self, now: float) -> list[RouteRequest]:
        """Timers (a dwell over, a train due, a retry): call at (or after) `next_deadline()`."""
        return self.update(now)

    def result(self, request: RouteRequest, accepted: bool, why: str | None, now: float) -> None:
        """What came of `request`: accepted by the interlocking, or not (`why`)."""
        self.pending.pop((request.station, request.route), None)
        key = (request.train, request.station, request.route)
        if accepted:
            self.granted[key] = _Grant(now)
            self.retry_at.pop(key, None)
            self._log(
                now,
                f"train {request.train}: {request.text} accepted",
                station=request.station,
                train=request.train,
            )
        else:
            self.retry_at[key] = (now + RETRY_S, str(why))
            self._log(
                now,
                f"train {request.train}: {request.text} not set: {why}",
                station=request.station,
                train=request.train,
            )

    # ------------------------------------------------------------------ queries

    def next_deadline(self) -> float | None:
        due: list[float] = [at for at, _ in self.retry_at.values()]
        due += [g.at + GRANT_GRACE_S for g in self.granted.values() if not g.seen]
        for train_id, p in self.progress.items():
            service = self.describer.trains[train_id].service
            if p.phase == "approach" and p.stop == 0:
                due.append(service.enters_at_s)
            if p.phase == "dwell":
                due += list(self._not_before(service.stops[p.stop], p, service))
        return min((d for d in due if d > self._now), default=None)

    def status(self) -> dict[str, Any]:
        """Stations on/off, and each train: where it is, what it does, what it waits for."""
        trains: list[dict[str, Any]] = []
        for t in self.describer._order():
            p = self.progress.get(t.id) or self._start(t)
            wanted = None
            if p.wanted is not None:
                st, route = p.wanted
                r = self.line.station(st).route(route)
                wanted = f"route {r.entry}-{r.exit} at station {st}"
            trains.append(
                {
                    kinds.TRAIN: t.id,
                    "track_circuits": list(t.footprint),
                    "berth": t.berth,
                    "lost": t.lost,
                    "state": self._state_text(t, p),
                    "next": wanted,
                    "waiting": p.waiting,
                }
            )
        for s in self.describer.expected:
            trains.append(
                {
                    kinds.TRAIN: s.id,
                    "track_circuits": [],
                    "berth": None,
                    "lost": False,
                    "state": f"not yet seen (expected at {s.appears_on})",
                    "next": None,
                    "waiting": None,
                }
            )
        return {
            "timetable": self.timetable.name,
            "stations": {str(st): on for st, on in sorted(self.enabled.items())},
            "trains": trains,
            "gone": list(self.describer.gone),
        }

    def last(self, count: int) -> list[ArsLogEntry]:
        return list(self.log)[-count:] if count > 0 else []

    # ------------------------------------------------------------------ the timetable

    def _start(self, t: DescribedTrain) -> _Progress:
        first = t.service.stops[0]
        if first.home_route is None:  # entered standing on its first platform
            return _Progress(0, "dwell", t.identified_at, first.track)
        return _Progress()

    def _station(self, number: int) -> Station:
        return self.line.station(number)

    def _platform(self, t: DescribedTrain, station: int) -> str | None:
        """The track whose own track circuits hold the whole train at `station` (None: none)."""
        if not t.footprint:
            return None
        st = self._station(station)
        tracks = set()
        for name in t.footprint:
            tc = st.track_circuit(name) if name in self._station_tcs[station] else None
            if tc is None or len(tc.tracks) != 1:
                return None
            tracks.add(tc.tracks[0])
        return tracks.pop() if len(tracks) == 1 else None

    def _advance(self, t: DescribedTrain, p: _Progress, now: float) -> None:
        """Move a train's progress on from where the describer has it."""
        stops = t.service.stops
        if p.phase == "approach" and set(t.footprint) & self._station_tcs[stops[p.stop].station]:
            p.phase = "arriving"
        if p.phase == "arriving":
            stop = stops[p.stop]
            track = self._platform(t, stop.station)
            if track is not None:
                p.track, p.arrived_at = track, now
                where = f"station {stop.station} track {track}"
                other = "" if track == stop.track else f" (timetabled: track {stop.track})"
                self._log(
                    now, f"train {t.id} arrived at {where}{other}", station=stop.station, train=t.id
                )
                last = p.stop == len(stops) - 1
                if last and not t.service.leaves_lab:
                    p.phase = "terminated"
                    self._log(
                        now, f"train {t.id} terminates at {where}", station=stop.station, train=t.id
                    )
                else:
                    p.phase = "dwell"
        if p.phase == "dwell":
            route = self._start_route(t, p)
            if route is not None and set(t.footprint) & set(route.track_circuits):
                p.stop += 1
                p.arrived_at = p.track = None
                p.phase = "approach" if p.stop < len(stops) else "leaving"

    def _start_route(self, t: DescribedTrain, p: _Progress) -> Route | None:
        stop = t.service.stops[p.stop]
        return start_route(
            self.line, self._station(stop.station), t.direction, p.track or stop.track
        )

    def _not_before(self, stop: Stop, p: _Progress, train: TimetableTrain) -> tuple[float, ...]:
        times = [train.enters_at_s, train.depart_s] if p.stop == 0 else []
        if p.arrived_at is not None:
            times.append(p.arrived_at + stop.dwell_s)
        return tuple(times)

    def _wanted(self, t: DescribedTrain, p: _Progress, now: float) -> _Want:
        """The route the train needs next and whether it must wait for it (see `_Want`)."""
        if t.lost:
            return _Want(None, None, f"lost at {t.berth}")
        if p.phase in ("arriving", "terminated", "leaving"):
            return _Want(None, None, None)
        stop = t.service.stops[p.stop]
        st = self._station(stop.station)
        if p.phase == "approach":
            assert stop.home_route is not None
            route: Route | None = st.route(stop.home_route)
            assert route is not None
            if t.footprint[-1] not in self._approach_zone(stop.station, route):
                return _Want(stop.station, route, "")  # not yet approaching
            due = t.service.enters_at_s if p.stop == 0 else now
        else:
            route = self._start_route(t, p)
            if route is None:
                why = f"no route out of station {stop.station} from track {p.track}"
                return _Want(stop.station, None, why)
            due = max(self._not_before(stop, p, t.service), default=now)
        if not self.enabled.get(stop.station, False):
            return _Want(stop.station, route, f"ARS off at station {stop.station}")
        if now < due:
            if p.phase == "dwell" and due == (p.arrived_at or 0.0) + stop.dwell_s:
                return _Want(stop.station, route, f"dwell until {due:.1f} s")
            return _Want(stop.station, route, f"not due until {due:.1f} s")
        return _Want(stop.station, route, None)

    def _approach_zone(self, station: int, route: Route) -> set[str]:
        """Where a train approaching `route`'s entry signal may be: the route's approach track
        circuits and the plain line the station owns behind the signal."""
        view = self.line.view(station)
        zone = set(route.approach)
        for iv in view.intervals:
            behind = iv.east == station if route.direction == "up" else iv.west == station
            if behind:
                zone.update(view.owned_half(iv))
        return zone

    # ------------------------------------------------------------------ may the route be set?

    def _check(
        self,
        t: DescribedTrain,
        station: int,
        route: Route,
        readings: dict[int, StationReading],
        occupancy: dict[str, bool | None],
        now: float,
    ) -> str | None:
        """None: ask for `route` now. Else why not ("" : it is on its way, nothing to log)."""
        reading = readings.get(station)
        if reading is None:
            return f"no indications from station {station} (link down or not yet synced)"
        if reading.mode != "center":
            return f"station {station} in {reading.mode or 'unknown'} mode"
        key = (t.id, station, route.name)
        if (station, route.name) in self.pending:
            mine = self.pending[(station, route.name)].train == t.id
            return "" if mine else f"route {route.entry}-{route.exit} asked for another train"
        grant = self.granted.get(key)
        if route.name in reading.routes_set:
            if grant is not None or not any(occupancy.get(tc) for tc in route.track_circuits):
                return ""  # set for this train: it will run in
            inside = {o.id for tc in route.track_circuits if (o := self.describer.train_at(tc))}
            who = ", ".join(f"train {x}" for x in sorted(inside)) or "a train"
            return f"route {route.entry}-{route.exit} still set, {who} in it"
        if grant is not None and not grant.seen:
            return ""  # accepted; its indication is on its way
        busy = self._set_or_asked(station, reading)
        conflicts = [
            c for c in route.conflicts if c in busy and self._in_the_way(station, c, route, reading)
        ]
        if conflicts:
            names = ", ".join(
                self._route_text(station, c)
                + (" (set)" if c in reading.routes_set else " (asked for)")
                for c in conflicts
            )
            return f"conflicts with route {names}"
        for tc in route.all_track_circuits:
            occ = occupancy.get(tc)
            if occ is not False:
                return f"{tc} {'occupied' if occ else 'occupancy unknown'}"
        for ps in route.all_points:
            pr = reading.points.get(ps.point)
            if pr is None or pr.position == "failed":
                return f"point {ps.point} failed (no detection)"
            if pr.locked and pr.position != ps.position:
                return f"point {ps.point} locked {pr.position.replace('_', ' ')}"
        iv = self.line.view(station).interval_of_exit(route)
        if iv is not None and reading.directions.get(iv.name) != route.direction:
            half = self.line.view(station).owned_half(iv)
            if any(occupancy.get(tc) is not False for tc in half):
                return f"interval {iv.name} occupied against the {route.direction} direction"
        retry = self.retry_at.get(key)
        if retry is not None and now < retry[0]:
            return f"not set ({retry[1]}), asking again at {retry[0]:.1f} s"
        return None

    def _in_the_way(
        self, station: int, conflict: str, route: Route, reading: StationReading
    ) -> bool:
        """Whether the set (or asked-for) route `conflict` (`other`) still keeps `route` out.

        The CTC sees route locking per route (RSI), not per track circuit, but it sees each
        point's lock (SLI). A point of `other`'s own path that shows unlocked means the train
        has run into `other` and released it up to there (sections release in order, taking
        their points with them): then `other` is no longer locked whole, and what it shares
        with `route` is free if each shared point shows unlocked and each shared track circuit
        lies in a released stretch -- in a section at or before one whose point shows
        unlocked, or in an overlap whose point shows unlocked. Anything the CTC cannot see
        released keeps `route` out."""

        def unlocked(point: str) -> bool:
            pr = reading.points.get(point)
            return pr is not None and not pr.locked

        st = self._station(station)
        other = st.route(conflict)
        if other.name not in reading.routes_set:
            return True  # asked for, not yet indicated: locked whole
        own_points = {s.point for s in other.points}
        section_of = {tc: i for i, sec in enumerate(other.release_sections) for tc in sec}
        released_to = -1  # the last section known released
        for i, sec in enumerate(other.release_sections):
            pts = {p for p in own_points if set(st.point(p).track_circuits) & set(sec)}
            if any(unlocked(p) for p in pts):
                released_to = i
        if released_to < 0:
            return True  # no sign a train has entered it
        overlap_released = any(unlocked(s.point) for s in other.overlap_points)
        mine = set(route.all_track_circuits) | {s.point for s in route.all_points}
        theirs = set(other.all_track_circuits) | {s.point for s in other.all_points}
        for element in mine & theirs:
            if element in own_points or element in {s.point for s in other.overlap_points}:
                if not unlocked(element):
                    return True
            elif element in section_of:
                if section_of[element] > released_to:
                    return True
            elif not overlap_released:
                return True
        return False

    def _set_or_asked(self, station: int, reading: StationReading) -> set[str]:
        """Routes of `station` set (indicated), asked for, or accepted but not yet indicated."""
        busy = set(reading.routes_set)
        busy |= {r for (st, r) in self.pending if st == station}
        busy |= {r for (_, st, r), g in self.granted.items() if st == station and not g.seen}
        return busy

    def _drop_stale_grants(self, readings: dict[int, StationReading], now: float) -> None:
        for key, grant in list(self.granted.items()):
            train, station, route = key
            reading = readings.get(station)
            if reading is None:
                continue
            text = self._route_text(station, route)
            entered = self._entered(train, station, route)
            if route in reading.routes_set:
                grant.seen = True
                if entered:
                    del self.granted[key]
            elif grant.seen:
                del self.granted[key]
                if not entered:
                    self._log(
                        now,
                        f"train {train}: route {text} at station {station} released "
                        "before the train entered it",
                        station=station,
                        train=train,
                    )
            elif now >= grant.at + GRANT_GRACE_S:
                del self.granted[key]
                self._log(
                    now,
                    f"train {train}: route {text} at station {station} accepted but "
                    f"not indicated set within {GRANT_GRACE_S:g} s",
                    station=station,
                    train=train,
                )

    def _entered(self, train: str, station: int, route: str) -> bool:
        t = self.describer.trains.get(train)
        if t is None:
            return True
        r = self._station(station).route(route)
        return bool(set(t.footprint) & set(r.track_circuits))

    # ------------------------------------------------------------------ log

    def _route_text(self, station: int, route: str) -> str:
        r = self._station(station).route(route)
        return f"{r.entry}-{r.exit}"

    def _wait(self, t: DescribedTrain, p: _Progress, why: str | None, now: float) -> None:
        if why == p.waiting:
            return
        p.waiting = why
        if why is None:
            return
        what = ""
        if p.wanted is not None:
            st, route = p.wanted
            what = f" for route {self._route_text(st, route)} at station {st}"
        self._log(
            now,
            f"train {t.id} waits{what}: {why}",
            station=p.wanted[0] if p.wanted else None,
            train=t.id,
        )

    def _log(
        self, now: float, text: str, station: int | None = None, train: str | None = None
    ) -> None:
        entry = ArsLogEntry(time=now, station=station, train=train, text=text)
        self.log.append(entry)
        if self.on_log is not None:
            self.on_log(entry)

    def _state_text(self, t: DescribedTrain, p: _Progress) -> str:
        stops = t.service.stops
        if t.lost:
            return f"lost at {t.berth}"
        if p.phase == "leaving":
            return "leaving the lab"
        stop = stops[p.stop]
        where = f"station {stop.station}"
        if p.phase == "approach":
            return f"running to {where}"
        if p.phase == "arriving":
            return f"arriving at {where}"
        if p.phase == "terminated":
            return f"terminated at {where} track {p.track}"
        return f"at {where} track {p.track}"
