"""The track-circuit emulator: owns the line, moves each train by the point blades as the
trackside holds them, turns train positions into occupancy, and hands each train the code of the
track circuit under its antenna (SPEC §6.4, §6.7).

A train is given as head and tail chainage (the antenna is at the head; a train whose head is above
its tail faces up) and, when it first appears, the station track it is put on (`TrainPosition`).
From then on the model keeps its actual path -- which track it is on between the points under it
(`TrainPath`) -- and moves it with each new position: the end that advances goes over the points
ahead (`station.geometry`), the other end follows the path. At a point met facing the train takes
the leg the blades lie in; met trailing against the blades it trails the point (forces the blades
over: the trackside loses its detection until a fault clear); blades moving or not in an end
position under a train derail it, and so does a point moved under it. A train booked on a track
(a timetable train) that finds itself on another where its booked track runs is misrouted. Each
such event is kept for the adapter (`take_events`) to log and tell the train and the trackside.

Blades are fed per station (`set_blades`); a point not reported yet lies normal (where a point
machine starts). Faults per track circuit: "failed_occupied", "failed_clear" (wrong side: a
train is not seen) and "no_code" (the code does not reach the antenna). Sans-I/O: positions and
blades in, no clock.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from ktcs_bench.atc.track_codes import AtcCode, most_restrictive
from ktcs_bench.station.geometry import LineGeometry, Track, beyond, meets
from ktcs_bench.station.model import Line, PointPosition, TrackCircuit

FAULTS = ("failed_occupied", "failed_clear", "no_code")
Blades = Literal["normal", "reverse", "moving", "none"]
BLADES: tuple[Blades, ...] = ("normal", "reverse", "moving", "none")
"""Where a point's blades are: in an end position, moving, or stopped between (not in one)."""
_BLADES: dict[str, Blades] = {b: b for b in BLADES}


@dataclass(frozen=True, slots=True)
class TrainPosition:
    train: str
    head_m: float
    tail_m: float
    track: str | None = "1"  # the station track it is put on, or booked on (see `booked`)
    booked: bool = False  # `track` is its booked track here: running off it is misrouting


@dataclass(frozen=True, slots=True)
class Crossing:
    """A point under (or at an end of) a train: where, and the leg the train is on."""

    position_m: float
    station: int
    point: str
    leg: PointPosition


@dataclass
class TrainPath:
    """Where a train actually is: from `lo` to `hi` (m), on `tracks[i]` between the crossings
    i-1 and i (len(tracks) == len(crossings) + 1, in chainage order)."""

    lo: float
    hi: float
    tracks: list[Track]
    crossings: list[Crossing] = field(default_factory=list)
    derailed: set[tuple[int, str]] = field(default_factory=set)
    misrouted: bool = False

    def stretches(self) -> list[tuple[float, float, Track]]:
        bounds = [self.lo, *(c.position_m for c in self.crossings), self.hi]
        return [(bounds[i], bounds[i + 1], t) for i, t in enumerate(self.tracks)]

    def track_at_end(self, upper: bool) -> Track:
        return self.tracks[-1] if upper else self.tracks[0]


@dataclass(frozen=True, slots=True)
class RailEvent:
    """Something the rails did to a train: `kind` trailed | derailed | misrouted; `leg` the
    position a trailed point's blades were forced to; `track` the track a misrouted train is on."""

    kind: str
    train: str
    text: str
    station: int | None = None
    point: str | None = None
    leg: PointPosition | None = None
    track: str | None = None


class TrackCircuitModel:
    booked_tracks_for_tests = False
    """Test-only, never set by the bench: when True a booked train runs along its booked track
    whatever the blades (facing it takes the leg to its booked track; no trailing, no derailing)
    -- the model before SPEC §6.7, so that a test shows the whole-system search catching a train
    run through a point not lying for it (tests/lab/test_system_safety.py)."""

    def __init__(self, line: Line) -> None:
        self.line = line
        self.geometry = LineGeometry(line)
        self.tcs: tuple[TrackCircuit, ...] = line.all_track_circuits()
        self._by_name = {t.name: t for t in self.tcs}
        # the circuits by where they start, for the few a train's axles can be in (every train
        # move asks; a line has tens of circuits, a train is over a handful)
        self._by_from = sorted(self.tcs, key=lambda t: t.from_m)
        self._froms = [t.from_m for t in self._by_from]
        self._longest = max((t.to_m - t.from_m for t in self.tcs), default=0.0)
        # the circuit under each train's antenna, for the head and track it was found for
        self._antenna: dict[str, tuple[float, bool, Track, str | None]] = {}
        self._dirty = True  # trains, paths or faults changed since the occupancy was last taken
        self._faults_changed = True  # ... faults among them
        self._last_shunted: set[str] | None = None  # the circuits shunted when it was
        self.trains: dict[str, TrainPosition] = {}
        self.paths: dict[str, TrainPath] = {}
        self.blades: dict[tuple[int, str], Blades] = {
            (st, p.name): "normal" for _, st, p in self.geometry.points
        }
        self.faults: dict[str, str] = {}
        self.codes: dict[str, AtcCode] = {}
        self.events: list[RailEvent] = []
        self._last = self.occupancy()

    # ------------------------------------------------------------------ inputs

    def update(self, trains: Iterable[TrainPosition]) -> dict[str, bool]:
        """New train positions (all trains: one missing is taken off); the occupancy changes."""
        given = list(trains)
        for gone in set(self.trains) - {t.train for t in given}:
            self._drop(gone)
        for t in given:
            self._move(t)
        return self._changes()

    def move(self, position: TrainPosition) -> dict[str, bool]:
        """One train's new position (put on the line if new); the occupancy changes.
        ValueError for a train put where its track does not run (nothing changes)."""
        self._move(position)
        return self._changes()

    def remove(self, train: str) -> dict[str, bool]:
        self._drop(train)
        return self._changes()

    def set_blades(self, station: int, blades: Mapping[str, str]) -> dict[str, bool]:
        """Where the blades of the station's points are (any of `BLADES`); a point moved under a
        train derails it. KeyError for an unknown point, ValueError for an unknown state."""
        for point, state in blades.items():
            self.geometry.point(station, point)  # KeyError on an unknown one
            if state not in BLADES:
                raise ValueError(f"blades of point {station} {point}: {state!r} is not one of "
                                 f"{', '.join(BLADES)}")  # fmt: skip
        for point, state in blades.items():
            self.blades[(station, point)] = _BLADES[state]
        for train, path in self.paths.items():
            self._under(train, path)
        self._dirty = True
        return self._changes()

    def take_events(self) -> list[RailEvent]:
        """What happened on the rails since the last call (trailed, derailed, misrouted)."""
        out, self.events = self.events, []
        return out

    def fail(self, tc: str, kind: str) -> dict[str, bool]:
        if kind not in FAULTS:
            raise ValueError(f"unknown track-circuit fault {kind!r} {FAULTS}")
        self._by_name[tc]  # KeyError on an unknown name
        self.faults[tc] = kind
        self._dirty = True
        self._faults_changed = True
        return self._changes()

    def clear_fault(self, tc: str | None = None) -> dict[str, bool]:
        if tc is None:
            self.faults.clear()
        else:
            self.faults.pop(tc, None)
        self._dirty = True
        self._faults_changed = True
        return self._changes()

    # ------------------------------------------------------------------ queries

    def shunted(self, tc: TrackCircuit) -> bool:
        """A train's axles are in the track circuit (before any fault)."""
        return self._shunted(tc, self._spans())

    def track_of(self, train: str) -> Track:
        """The track the train's head is on (None: the plain line)."""
        t = self.trains[train]
        return self.paths[train].track_at_end(t.head_m >= t.tail_m)

    def derailed(self, train: str) -> bool:
        return bool(self.paths[train].derailed)

    def _spans(self) -> list[tuple[float, float, Track]]:
        """Each train's axles: (lowest, highest chainage, track) per stretch of its path."""
        return [s for p in self.paths.values() for s in p.stretches()]

    def _shunted(self, tc: TrackCircuit, spans: list[tuple[float, float, Track]]) -> bool:
        for lo, hi, track in spans:
            if lo < tc.to_m and hi > tc.from_m and self.geometry.carries(tc, track):
                return True
        return False

    def occupancy(self) -> dict[str, bool]:
        """Every track circuit of the line: occupied as its receiver reports it."""
        return self._occupancy(self._shunted_names(self._spans()))

    def _occupancy(self, shunted: set[str]) -> dict[str, bool]:
        out = dict.fromkeys(self._by_name, False)
        for name in shunted:
            out[name] = True
        for name, fault in self.faults.items():
            if fault == "failed_occupied":
                out[name] = True
            elif fault == "failed_clear":
                out[name] = False
        return out

    def _shunted_names(self, spans: list[tuple[float, float, Track]]) -> set[str]:
        """The circuits some span shunts (`_shunted` over the circuits that can overlap it)."""
        names: set[str] = set()
        froms, by_from, carries = self._froms, self._by_from, self.geometry.carries
        for lo, hi, track in spans:
            # only a circuit starting below `hi` and less than the longest circuit below `lo`
            # can reach into (lo, hi)
            for i in range(bisect_left(froms, lo - self._longest), bisect_left(froms, hi)):
                tc = by_from[i]
                if tc.to_m > lo and tc.name not in names and carries(tc, track):
                    names.add(tc.name)
        return names

    def set_codes(self, codes: Mapping[str, AtcCode]) -> None:
        """Codes from the wayside ATCs, per track circuit."""
        self.codes.update(codes)

    def under_antenna(self, train: str) -> str | None:
        """The track circuit under the train's head, on the track the head is actually on."""
        t = self.trains[train]
        up = t.head_m >= t.tail_m
        track = self.paths[train].track_at_end(up)
        known = self._antenna.get(train)
        if known is not None and known[0] == t.head_m and known[1] == up and known[2] == track:
            return known[3]
        found: str | None = None
        head, carries, by_from = t.head_m, self.geometry.carries, self._by_from
        # the first of `tcs` (chainage order, as `_by_from`) that holds the head: only those
        # starting at most the longest circuit (and a metre for rounding) below it can
        lo = bisect_left(self._froms, head - self._longest - 1.0)
        for i in range(lo, bisect_right(self._froms, head)):
            tc = by_from[i]
            inside = tc.from_m <= head < tc.to_m if up else tc.from_m < head <= tc.to_m
            if inside and carries(tc, track):
                found = tc.name
                break
        self._antenna[train] = (t.head_m, up, track, found)
        return found

    def code_for(self, train: str) -> AtcCode | None:
        """The code the train's antenna picks up; None when no code reaches it. A code given for
        the other direction of travel (tail -> head) is no proceed for this train: it reads the
        most restrictive code."""
        tc = self.under_antenna(train)
        if tc is None or self.faults.get(tc) == "no_code":
            return None
        code = self.codes.get(tc)
        t = self.trains[train]
        running = "up" if t.head_m >= t.tail_m else "down"
        if code is not None and code.direction is not None and code.direction != running:
            return most_restrictive(self.line, -code.gradient_permille)
        return code

    # ------------------------------------------------------------------ the path

    def _drop(self, train: str) -> None:
        self.trains.pop(train, None)
        self.paths.pop(train, None)
        self._antenna.pop(train, None)
        self._dirty = True

    def _move(self, t: TrainPosition) -> None:
        if t.train in self.paths and self.trains.get(t.train) == t:
            # where it was: its path, the points under it and its booking are as they were
            # (blades moved since were looked at under every train by `set_blades`)
            return
        self._dirty = True
        lo, hi = min(t.head_m, t.tail_m), max(t.head_m, t.tail_m)
        path = self.paths.get(t.train)
        if path is None:
            # put on the line: its rear on its track, its front run out over the points between
            up = t.head_m >= t.tail_m
            rear = t.tail_m
            path = TrainPath(rear, rear, [self.geometry.track_at(rear, t.track)])
            self._extend(t.train, path, t.head_m, upper=up)
            self.paths[t.train] = path
        else:
            booked = t.track if t.booked and self.booked_tracks_for_tests else None
            if hi > path.hi:
                self._extend(t.train, path, hi, upper=True, booked=booked)
            if lo < path.lo:
                self._extend(t.train, path, lo, upper=False, booked=booked)
        self._trim(path, lo, hi)
        self.trains[t.train] = t
        if not (t.booked and self.booked_tracks_for_tests):
            self._under(t.train, path)
        if t.booked and t.track is not None and not path.misrouted:
            actual = path.track_at_end(t.head_m >= t.tail_m)
            if actual is not None and actual != t.track and self.geometry.runs(t.track, t.head_m):
                path.misrouted = True
                self.events.append(RailEvent(
                    "misrouted", t.train, f"misrouted: train {t.train} on track {actual} at "
                    f"{t.head_m:.0f} m, booked on track {t.track}", track=actual,
                ))  # fmt: skip

    def _extend(
        self, train: str, path: TrainPath, to: float, upper: bool, booked: str | None = None
    ) -> None:
        """Run the path's upper (or lower) end out to `to` over the points on its way (`booked`:
        along that track whatever the blades, `booked_tracks_for_tests`)."""
        start = path.hi if upper else path.lo
        for station, point in self.geometry.passed(start, to):
            track = path.track_at_end(upper)
            meeting = meets(point, track, upward=upper)
            if meeting is None:
                continue
            key = (station, point.name)
            blades = self.blades[key]
            leg: PointPosition
            if meeting == "toe":  # facing: the leg the blades lie in (normal if they lie in none)
                leg = "reverse" if blades == "reverse" else "normal"
            else:
                leg = meeting
            if booked is not None:
                leg = "reverse" if meeting == "toe" and point.reverse == booked else leg
                if meeting == "toe" and point.normal == booked:
                    leg = "normal"
            elif blades not in ("normal", "reverse"):
                self._derail(train, path, station, point.name)
            elif meeting != "toe" and blades != leg:
                self.blades[key] = leg  # forced over by the wheels
                self.events.append(RailEvent(
                    "trailed", train, f"trailed point {station} {point.name} (train {train}, "
                    f"blades {blades}, trailed from the {leg} leg)", station, point.name, leg,
                ))  # fmt: skip
            crossing = Crossing(point.position_m, station, point.name, leg)
            onto = beyond(point, meeting, leg)
            if upper:
                path.crossings.append(crossing)
                path.tracks.append(onto)
                path.hi = point.position_m
            else:
                path.crossings.insert(0, crossing)
                path.tracks.insert(0, onto)
                path.lo = point.position_m
        if upper:
            path.hi = max(path.hi, to)
        else:
            path.lo = min(path.lo, to)

    @staticmethod
    def _trim(path: TrainPath, lo: float, hi: float) -> None:
        """The path cut to the train's new extent (a crossing at an end stays: the end is over)."""
        while path.crossings and path.crossings[-1].position_m > hi:
            path.crossings.pop()
            path.tracks.pop()
        while path.crossings and path.crossings[0].position_m < lo:
            path.crossings.pop(0)
            path.tracks.pop(0)
        path.lo, path.hi = lo, hi

    def _under(self, train: str, path: TrainPath) -> None:
        """A point under the train whose blades are not (any longer) on its leg derails it."""
        for c in path.crossings:
            if path.lo < c.position_m < path.hi and self.blades[(c.station, c.point)] != c.leg:
                self._derail(train, path, c.station, c.point)

    def _derail(self, train: str, path: TrainPath, station: int, point: str) -> None:
        if (station, point) in path.derailed:
            return
        path.derailed.add((station, point))
        blades = self.blades[(station, point)]
        self.events.append(RailEvent(
            "derailed", train, f"derailed {station} {point} (train {train}, blades {blades})",
            station, point,
        ))  # fmt: skip

    def _changes(self) -> dict[str, bool]:
        if not self._dirty:  # nothing the occupancy is made of changed: nothing can
            return {}
        self._dirty = False
        shunted = self._shunted_names(self._spans())
        if shunted == self._last_shunted and not self._faults_changed:
            return {}  # the same circuits shunted, the same faults: the same occupancy
        self._last_shunted, self._faults_changed = shunted, False
        now = self._occupancy(shunted)
        changed = {k: v for k, v in now.items() if self._last.get(k) != v}
        self._last = now
        return changed
