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

A departure into an interval between two stations needs that interval's traffic permission
(SPEC §6.6): where its station does not hold it, ARS asks for it first (a `DirectionRequest`,
`ctc direction`) and the route once it is held -- never against a train in the interval or a
departure route into it from the other end, read from both ends' indications; of two trains ready
to depart into one interval from its two ends, the one standing on the other's arrival track goes
first, else the first in timetable order, and the other waits saying for whom (docs/ars.md).

A CTC that starts with trains on the line picks them up from its first whole picture
(`Describer.pick_up`) and takes each on from where it stands.

A station showing every one of its track circuits occupied shows its interlocking's fail-safe
picture (its ATC link down, or up and not yet reporting): ARS reads that as occupancy not known,
not as trains -- it steps, clears and identifies no train, and sets no route over it.

Inputs: `update(now)` after the CTC's indication tables changed (it reads them through the
`CtcModel`), `handle_timer(now)` at `next_deadline()` (a dwell ending, a train becoming due, a
retry), `switch(station, on, now)` and `result(request, accepted, why, now)` with what came of a
request. `update` and `handle_timer` return the requests to send (`RouteRequest`,
`DirectionRequest`), in the CTC desk's words (`request.command`). A rejected or unanswered request is asked again after `RETRY_S`; an accepted
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
from ktcs_bench.station.model import Direction, Interval, Route, Station
from ktcs_bench.station.timetable import Stop, Timetable, TimetableTrain, start_route

RETRY_S = 5.0  # a rejected or unanswered request: ask again no sooner
GRANT_GRACE_S = 10.0  # an accepted request whose route is not indicated set by then: ask again
LOG_KEEP = 2_000  # log entries kept
ASKED_S = 5.0  # the permission asked for and the ask accepted: not asked again for so long
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


@dataclass(frozen=True, slots=True)
class DirectionRequest:
    """An interval's traffic permission ARS asks for at `station`, ahead of `train`'s departure
    into it (SPEC §6.6): the station's IXL asks its neighbour."""

    train: str
    station: int
    interval: str
    holder: int | None  # who held it when asked

    @property
    def command(self) -> messages.AskDirection:
        """The request as the CTC desk takes it (`CtcModel.action`)."""
        return messages.AskDirection(station=self.station, interval=self.interval)

    @property
    def text(self) -> str:
        return f"the permission of interval {self.interval} at station {self.station}"


ArsRequest = RouteRequest | DirectionRequest
"""What ARS sends through the desk: a route, or an interval's permission ahead of one."""


@dataclass(frozen=True, slots=True)
class _Contender:
    """A train ready to depart into an interval but for its permission: who goes first is by
    the timetable (`key`: when its departure came due, then its place in the timetable)."""

    train: str
    station: int
    key: tuple[float, int]


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
    picked: bool = False  # picked up on the line at the CTC's start: its first times are past


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
        # interval permissions: (station, interval) -> request sent, no result yet
        self.pending_direction: dict[tuple[int, str], DirectionRequest] = {}
        self.asked: dict[tuple[int, str], float] = {}  # -> asked (accepted) until then
        self.direction_retry: dict[tuple[int, str], tuple[float, str]] = {}  # -> (when, why)
        self.directions_asked = 0
        self._contenders: dict[str, list[_Contender]] = {}  # interval -> ready to depart into it
        self._picked_up = False  # the trains on the line at the start have been picked up
        self._order = {t.id: i for i, t in enumerate(timetable.trains)}
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

    def update(self, now: float) -> list[ArsRequest]:
        """The indication tables changed (or time passed): follow the trains, ask for routes (and
        for the permission of the interval a departure leads into)."""
        self._now = max(self._now, now)
        readings = self._readings()
        occupancy: dict[str, bool | None] = {}
        for reading in readings.values():
            occupancy.update(self._occupancy(reading))
        if not self._picked_up and self._whole_picture(readings, occupancy):
            self._picked_up = True  # the trains already on the line, once, at the first picture
            for e in self.describer.pick_up(occupancy, now, self._hints(readings)):
                self._log(now, e.text, train=e.train)
        for e in self.describer.update(occupancy, now):
            self._log(now, e.text, train=e.train)
        for train_id in list(self.progress):
            if train_id not in self.describer.trains:
                del self.progress[train_id]
        self._drop_stale_grants(readings, now)
        wants: list[tuple[DescribedTrain, _Progress, _Want]] = []
        for t in self.describer._order():
            p = self.progress.setdefault(t.id, self._start(t))
            self._advance(t, p, now)
            wants.append((t, p, self._wanted(t, p, now)))
        self._contenders = self._ready_to_depart(wants, readings, occupancy, now)
        requests: list[ArsRequest] = []
        claimed: dict[tuple[int, str], str] = {}  # (station, entry signal) -> the leading train
        for t, p, want in wants:
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
            if why is None:
                why, ask = self._direction(t, p, station, route, readings, occupancy, now)
                if ask is not None:
                    self.pending_direction[(ask.station, ask.interval)] = ask
                    self.directions_asked += 1
                    self._wait(t, p, why, now)
                    self._log(now, f"train {t.id}: asks for {ask.text}" + (
                        f" (held by {ask.holder})" if ask.holder is not None else ""),
                        station=station, train=t.id)  # fmt: skip
                    requests.append(ask)
                    continue
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

    # ------------------------------------------------------------------ interval permissions

    def _departure_interval(self, station: int, route: Route) -> Interval | None:
        """The interval between two stations of the lab that `route` departs into (None: it
        departs into none, or into one at the lab's edge, whose direction is fixed)."""
        iv = self.line.view(station).interval_of_exit(route)
        return None if iv is None or iv.boundary else iv

    def _ready_to_depart(
        self,
        wants: list[tuple[DescribedTrain, _Progress, _Want]],
        readings: dict[int, StationReading],
        occupancy: dict[str, bool | None],
        now: float,
    ) -> dict[str, list[_Contender]]:
        """Per interval, the trains whose departure into it could be asked for now but for its
        permission, first in timetable order: when each departure came due, then the train's
        place in the timetable."""
        out: dict[str, list[_Contender]] = {}
        for t, p, want in wants:
            if want.why is not None or want.route is None or want.station is None:
                continue
            if p.phase != "dwell":
                continue
            iv = self._departure_interval(want.station, want.route)
            if iv is None:
                continue
            if self._check(t, want.station, want.route, readings, occupancy, now) not in (None, ""):
                continue  # held up by something else at its own station
            stop = t.service.stops[p.stop]
            due = max(self._not_before(stop, p, t.service), default=p.arrived_at or 0.0)
            key = (due, self._order.get(t.id, len(self._order)))
            out.setdefault(iv.name, []).append(_Contender(t.id, want.station, key))
        for group in out.values():
            group.sort(key=lambda c: c.key)
        return out

    def _direction(
        self,
        t: DescribedTrain,
        p: _Progress,
        station: int,
        route: Route,
        readings: dict[int, StationReading],
        occupancy: dict[str, bool | None],
        now: float,
    ) -> tuple[str | None, DirectionRequest | None]:
        """May `t`'s departure `route` be asked for as far as its interval's permission goes?
        (None, None): yes. (why, None): it waits. (why, request): ask for the permission first.

        ARS never asks for it against a train in the interval or a route into it from the other
        end (read from both ends' indications, and its own requests), and of two trains ready
        to depart into it from its two ends the first in timetable order goes -- unless the
        other stands on the track it would arrive at and needs the interval itself: then that
        one goes first (else the two would lock each other up)."""
        iv = self._departure_interval(station, route)
        if iv is None:
            return None, None
        holds, asks = readings[station].permission.get(iv.name, (None, None))
        other = iv.east if station == iv.west else iv.west
        if holds is None or self._not_worked(iv, readings):
            return None, None  # its interlockings work no permission: nothing to ask for
        first = self._goes_first(t, p, station, iv)
        if first is not None:
            return first, None
        if holds:
            return None, None
        far = readings.get(other)
        if far is None:
            return f"interval {iv.name} not held here, no indications from station {other}", None
        reading = self.model.interval(iv)
        held = (f"interval {iv.name} held by {reading.holder}" if reading.holder is not None
                else f"interval {iv.name}: no end holds its permission")  # fmt: skip
        against = self._against(t, iv, other, far, occupancy)
        if against is not None:
            return f"{held}, {against}", None
        if reading.holder is None:
            return held, None  # the link between the two resyncs: nothing to ask of anyone
        key = (station, iv.name)
        if key in self.pending_direction or asks or now < self.asked.get(key, -1.0):
            return f"{held}, asked for it", None
        retry = self.direction_retry.get(key)
        if retry is not None and now < retry[0]:
            return f"{held}, not given ({retry[1]}), asking again at {retry[0]:.1f} s", None
        self.direction_retry.pop(key, None)
        return f"{held}, asked for it", DirectionRequest(t.id, station, iv.name, reading.holder)

    @staticmethod
    def _not_worked(iv: Interval, readings: dict[int, StationReading]) -> bool:
        """Both ends show the interval's direction alike, yet neither holds nor asks for its
        permission: interlockings that work no permission (from before SPEC §6.6) -- each
        shows its direction, and departures are theirs to refuse. (Where the permission is
        worked, an end showing a direction knows its holder; in a handover or a lost one the
        ends do not show one alike.)"""
        ends = [readings.get(iv.west), readings.get(iv.east)]
        if any(r is None for r in ends):
            return False
        shown = {r.directions.get(iv.name) for r in ends if r is not None}
        perm = [r.permission.get(iv.name, (None, None)) for r in ends if r is not None]
        return len(shown) == 1 and None not in shown and not any(h or a for h, a in perm)

    def _against(
        self,
        t: DescribedTrain,
        iv: Interval,
        other: int,
        far: StationReading,
        occupancy: dict[str, bool | None],
    ) -> str | None:
        """What in `iv` or at its other end `other` a departure of `t`'s into it would meet:
        a train in it, a circuit of it occupied (or not known), a route into it set (or asked
        for, by ARS) at the other end. None: nothing."""
        for tc in iv.track_circuits:
            o = self.describer.train_at(tc)
            if o is not None and o.id != t.id:
                return f"train {o.id} in it"
        for tc in iv.track_circuits:
            occ = occupancy.get(tc)
            if occ is not False:
                return f"{tc} {'occupied' if occ else 'occupancy unknown'}"
        view = self.line.view(other)
        for r in self._set_or_asked(other, far):
            exit_iv = view.interval_of_exit(self._station(other).route(r))
            if exit_iv is not None and exit_iv.name == iv.name:
                how = "set" if r in far.routes_set else "asked for"
                return f"route {self._route_text(other, r)} into it {how} at station {other}"
        return None

    def _goes_first(
        self, t: DescribedTrain, p: _Progress, station: int, iv: Interval
    ) -> str | None:
        """Why another train departs into `iv` before `t` (None: `t` may go first)."""
        ready = self._contenders.get(iv.name, [])
        mine = next((c for c in ready if c.train == t.id), None)
        blocker = self._standing_on_my_track(t, p, iv)
        if blocker is not None:
            bp = self.progress[blocker]
            if not self._mutual(blocker, iv):
                far = iv.east if station == iv.west else iv.west
                return (f"interval {iv.name}: train {blocker} stands on track {bp.track} "
                        f"at {far} and needs it, it goes first")  # fmt: skip
            # each stands on the other's track: the timetable locks them up; its order decides
            other_key = next((c.key for c in ready if c.train == blocker), None)
            if mine is not None and other_key is not None and other_key < mine.key:
                return (f"interval {iv.name}: trains {t.id} and {blocker} each stand on the "
                        f"other's track; {blocker} goes first (timetable order)")  # fmt: skip
            return None
        rivals = [c for c in ready if c.station != station
                  and (self._blocked(c.train, iv) is None or self._mutual(c.train, iv))
                  and (c.station, iv.name) not in self.direction_retry]  # fmt: skip
        # (a rival whose ask was refused lets this end go meanwhile: no waiting on a train
        # that cannot have the permission, the link between the two down, say)
        if mine is None or not rivals or mine.key <= rivals[0].key:
            return None
        return f"interval {iv.name} given to train {rivals[0].train} first (timetable order)"

    def _blocked(self, train: str, iv: Interval) -> str | None:
        t, p = self.describer.trains.get(train), self.progress.get(train)
        return None if t is None or p is None else self._standing_on_my_track(t, p, iv)

    def _mutual(self, train: str, iv: Interval) -> bool:
        """`train` stands on the arrival track of the train standing on its own (a lock-up the
        timetable makes): each would wait for the other."""
        other = self._blocked(train, iv)
        return other is not None and self._blocked(other, iv) == train

    def _standing_on_my_track(self, t: DescribedTrain, p: _Progress, iv: Interval) -> str | None:
        """A train standing at `iv`'s far end on the track `t` is booked to arrive at there, and
        going the other way (so it needs `iv` itself): its number, else None."""
        stops = t.service.stops
        if p.stop + 1 >= len(stops):
            return None
        nxt = stops[p.stop + 1]
        if nxt.station not in (iv.west, iv.east):
            return None
        for other_id, op in self.progress.items():
            o = self.describer.trains.get(other_id)
            if o is None or o.direction == t.direction or other_id == t.id:
                continue
            if op.phase in ("dwell", "terminated") and op.track == nxt.track:
                if o.service.stops[op.stop].station == nxt.station:
                    return other_id
        return None

    def _whole_picture(
        self, readings: dict[int, StationReading], occupancy: dict[str, bool | None]
    ) -> bool:
        """Every station's indications known, none showing its fail-safe picture."""
        return set(readings) == set(self.model.models) and all(
            v is not None for v in occupancy.values()
        )

    def _hints(self, readings: dict[int, StationReading]) -> dict[str, Direction]:
        """The direction the indications show over each circuit they show one for: an
        interval's traffic direction, a set route's direction (for picking trains up)."""
        out: dict[str, Direction] = {}
        for st, reading in readings.items():
            view = self.line.view(st)
            for iv in view.intervals:
                d = reading.directions.get(iv.name)
                if d == "up":
                    out.update(dict.fromkeys(iv.track_circuits, "up"))
                elif d == "down":
                    out.update(dict.fromkeys(iv.track_circuits, "down"))
            for name in sorted(reading.routes_set):
                route = self._station(st).route(name)
                out.update(dict.fromkeys(route.track_circuits, route.direction))
        return out

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

    def handle_timer(self, now: float) -> list[ArsRequest]:
        """Timers (a dwell over, a train due, a retry): call at (or after) `next_deadline()`."""
        return self.update(now)

    def result(self, request: ArsRequest, accepted: bool, why: str | None, now: float) -> None:
        """What came of `request`: accepted by the interlocking, or not (`why`)."""
        if isinstance(request, DirectionRequest):
            key2 = (request.station, request.interval)
            self.pending_direction.pop(key2, None)
            if accepted:
                self.asked[key2] = now + ASKED_S
                self.direction_retry.pop(key2, None)
            else:
                self.direction_retry[key2] = (now + RETRY_S, str(why))
            verdict = "asked" if accepted else f"not asked: {why}"
            self._log(now, f"train {request.train}: {request.text} {verdict}",
                      station=request.station, train=request.train)  # fmt: skip
            return
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
        due += [at for at, _ in self.direction_retry.values()] + list(self.asked.values())
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
        if t.picked_up:
            return self._picked(t)
        first = t.service.stops[0]
        if first.home_route is None:  # entered standing on its first platform
            return _Progress(0, "dwell", t.identified_at, first.track)
        return _Progress()

    def _picked(self, t: DescribedTrain) -> _Progress:
        """Where in its timetable a train picked up on the line stands, from where it is: on a
        platform of a stop (dwelling there from now; terminated at its last), in a stop's station
        short of its stop point (arriving), or on the way to the next stop ahead of it. Its
        first stop's times are not waited for again: it was on its way before the CTC started."""
        stops, now = t.service.stops, t.identified_at
        head = self.describer.circuits[t.berth]
        up = t.direction == "up"
        for k, stop in enumerate(stops):
            station = self._station(stop.station)
            if not set(t.footprint) & {c.name for c in station.track_circuits}:
                continue
            track = self._platform(t, stop.station)
            if track is not None:
                last = k == len(stops) - 1 and not t.service.leaves_lab
                p = _Progress(k, "terminated" if last else "dwell", now, track, picked=True)
            elif (head.to_m <= stop.stop_m + 1e-6) if up else (head.from_m >= stop.stop_m - 1e-6):
                p = _Progress(k, "arriving", picked=True)
            else:
                p = _Progress(k + 1, "approach" if k + 1 < len(stops) else "leaving", picked=True)
            self._log(now, f"train {t.id}: {self._state_text(t, p)}", stop.station, t.id)
            return p
        for k, stop in enumerate(stops):
            tcs = self._station(stop.station).track_circuits
            lo, hi = min(c.from_m for c in tcs), max(c.to_m for c in tcs)
            if (lo >= head.to_m - 1e-6) if up else (hi <= head.from_m + 1e-6):
                p = _Progress(k, "approach", picked=True)
                break
        else:
            p = _Progress(len(stops), "leaving", picked=True)
        self._log(now, f"train {t.id}: {self._state_text(t, p)}", train=t.id)
        return p

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
        times = [train.enters_at_s, train.depart_s] if p.stop == 0 and not p.picked else []
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
            due = t.service.enters_at_s if p.stop == 0 and not p.picked else now
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
