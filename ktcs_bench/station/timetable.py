"""Timetables: which trains run, with what train data, where they start, and where they stop.

A timetable file (`emulators/timetables/*.yaml`, and the one `ktcs-bench line generate` writes;
format in docs/ars.md) names the line it runs on (`line`, optional, relative to the file), its
train data by name (`train_data`: length, top speed, traction and brake rates -- seed 001
Table 1), and its trains. A train has an id, its data (`train`), a direction, and its stops in
running order: station, platform track, where its front stops (`stop_m`) and how long it stands
there (`dwell_s`). It starts standing at its first stop and leaves it at `depart_s` -- or, with
`enters: {track_circuit, at_s}`, it comes onto the line at that track circuit, not before `at_s`
and only once the track circuits it takes there are clear (`train.entry`), and runs to its first
stop. It ends at its last stop unless it `leaves_lab`. Times are seconds
from the start of the lab (the CTC's start).

`load_timetable(path, line)` checks a file against the line it runs on and resolves, for each
stop, the two routes automatic route setting asks for: the home route from the station's home
signal into the stop's track (none where the train starts standing on it) and the starting route
from the track's starting signal out into the next interval (none at the last stop, unless the
train leaves the lab). Every problem is one ConfigError naming the file and the key path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ktcs_bench.datafiles import load_mapping
from ktcs_bench.errors import excerpt
from ktcs_bench.schema import convert
from ktcs_bench.station.loader import _Doc
from ktcs_bench.station.model import (
    DIRECTIONS,
    Direction,
    Line,
    Route,
    Signal,
    Station,
    TrackCircuit,
)
from ktcs_bench.station.shapes import (
    StopShape,
    TimetableShape,
    TimetableTrainShape,
    TrainDataShape,
)

TRAIN_DATA_KEYS = (
    "length_m",
    "max_speed_kmh",
    "traction_kmh_per_s",
    "service_brake_kmh_per_s",
    "emergency_brake_kmh_per_s",
)


@dataclass(frozen=True, slots=True)
class TrainData:
    """A train's physical data, by name (seed 001 Table 1: 200 m, 80 km/h, 3 / 3 / 4 km/h/s)."""

    name: str
    length_m: float
    max_speed_kmh: float
    traction_kmh_per_s: float
    service_brake_kmh_per_s: float
    emergency_brake_kmh_per_s: float


@dataclass(frozen=True, slots=True)
class Stop:
    """A stop at a station's platform track, with the routes in and out that it needs."""

    station: int
    track: str
    stop_m: float  # where the train's front stops
    dwell_s: float
    home_route: str | None  # home signal -> this track (None: the train starts standing here)
    start_route: str | None  # this track's starting signal -> the next interval (None: ends here)


@dataclass(frozen=True, slots=True)
class Entry:
    """Where and from when a train comes onto the line."""

    track_circuit: str
    at_s: float


@dataclass(frozen=True, slots=True)
class TimetableTrain:
    id: str
    direction: Direction
    data: TrainData
    stops: tuple[Stop, ...]
    depart_s: float = 0.0  # it leaves its first stop no sooner
    enters: Entry | None = None  # None: it starts standing at its first stop
    leaves_lab: bool = False
    appears_on: str = ""  # the track circuit where it is first seen (entry or first platform)

    @property
    def enters_at_s(self) -> float:
        """No route of its own is set before this."""
        return self.enters.at_s if self.enters is not None else 0.0


@dataclass(frozen=True)
class Timetable:
    name: str
    file: str
    trains: tuple[TimetableTrain, ...]

    def train(self, train_id: str) -> TimetableTrain:
        for t in self.trains:
            if t.id == train_id:
                return t
        raise KeyError(train_id)


# ---------------------------------------------------------------------------------------------
# the routes a stop needs


def home_signal(station: Station, direction: Direction) -> Signal | None:
    return next((s for s in station.signals if s.kind == "home" and s.direction == direction), None)


def starting_signal(station: Station, direction: Direction, track: str) -> Signal | None:
    return next(
        (
            s
            for s in station.signals
            if s.kind == "starting" and s.direction == direction and s.track == track
        ),
        None,
    )


def home_route(station: Station, direction: Direction, track: str) -> Route | None:
    """The route from the station's home signal (facing `direction`) into platform `track`."""
    home, start = home_signal(station, direction), starting_signal(station, direction, track)
    if home is None or start is None:
        return None
    return next((r for r in station.routes if r.entry == home.name and r.exit == start.name), None)


def start_route(line: Line, station: Station, direction: Direction, track: str) -> Route | None:
    """The route from `track`'s starting signal out of the station into the next interval."""
    start = starting_signal(station, direction, track)
    if start is None:
        return None
    view = line.view(station.number)
    return next(
        (r for r in station.routes if r.entry == start.name and view.interval_of_exit(r)),
        None,
    )


def next_station(line: Line, station: int, route: Route) -> int | None:
    """The station at the far end of the interval `route` leads into (None: the lab's edge)."""
    iv = line.view(station).interval_of_exit(route)
    if iv is None or iv.boundary:
        return None
    return iv.east if route.direction == "up" else iv.west


# ---------------------------------------------------------------------------------------------
# the file


def platform_circuits(station: Station, track: str) -> tuple[TrackCircuit, ...]:
    """The track circuits that carry `track` alone at `station` (where a train stands at it)."""
    return tuple(t for t in station.track_circuits if t.tracks == (track,))


class _TimetableRefs:
    """What a timetable's trains refer to: the line, its track circuits and the train data."""

    def __init__(self, doc: _Doc, line: Line, data: dict[str, TrainData]) -> None:
        self.doc = doc
        self.line = line
        self.tcs = {t.name: t for t in line.all_track_circuits()}
        self.data = data

    def number(self, value: float, place: str) -> float:
        if not math.isfinite(value) or value < 0:
            raise self.doc.fail(place, f"must be a finite number >= 0, not {excerpt(value)}")
        return value


def _train_data(doc: _Doc, r: _TimetableRefs, table: dict[Any, Any]) -> dict[str, TrainData]:
    data: dict[str, TrainData] = {}
    for key, item in table.items():
        here = f"train_data.{key}"
        o = convert(item, TrainDataShape, doc.file, here)
        values = [r.number(getattr(o, k), f"{here}.{k}") for k in TRAIN_DATA_KEYS]
        for k, v in zip(TRAIN_DATA_KEYS, values, strict=True):
            if v <= 0:
                raise doc.fail(f"{here}.{k}", "must be positive")
        data[str(key)] = TrainData(str(key), *values)
    return data


def _stop(
    r: _TimetableRefs,
    o: StopShape,
    here: str,
    train: tuple[Direction, float, bool],
    last: bool,
    starts_here: bool,
) -> Stop:
    """One stop of a train running `direction`, `length` m long, that `leaves` the lab or not."""
    direction, length, leaves = train
    line, number_ = r.line, o.station
    if number_ not in line.stations:
        raise r.doc.fail(f"{here}.station", f"station {number_} is not on the line {line.name}")
    st = line.station(number_)
    track = str(o.track)
    if track not in st.tracks:
        raise r.doc.fail(
            f"{here}.track",
            f"station {number_} has no track {excerpt(track)} (tracks: {', '.join(st.tracks)})",
        )
    stop_m = o.stop_m
    rear = stop_m - length if direction == "up" else stop_m + length
    platform = platform_circuits(st, track)
    if not any(t.covers(stop_m) and t.covers(rear) for t in platform):
        where = ", ".join(f"{t.name} ({t.from_m:g}-{t.to_m:g} m)" for t in platform)
        raise r.doc.fail(
            f"{here}.stop_m",
            f"a {length:g} m train stopping at {stop_m:g} m "
            f"does not stand wholly on track {track}'s circuit {where or '(none)'}",
        )
    start = start_route(line, st, direction, track)
    if start is None and (not last or leaves):
        raise r.doc.fail(
            f"{here}.track", f"no {direction} route out of station {number_} from track {track}"
        )
    home = None if starts_here else home_route(st, direction, track)
    if home is None and not starts_here:
        raise r.doc.fail(
            f"{here}.track",
            f"no {direction} route from the home signal of station {number_} into track {track}",
        )
    return Stop(
        number_,
        track,
        stop_m,
        r.number(o.dwell_s, f"{here}.dwell_s"),
        None if home is None else home.name,
        start.name if start is not None and (not last or leaves) else None,
    )


def _stops(
    r: _TimetableRefs, o: TimetableTrainShape, place: str, direction: Direction, kind: str
) -> list[Stop]:
    """A train's stops, each reached from the one before."""
    if not o.stops:
        raise r.doc.fail(f"{place}.stops", "a train stops at one station at least")
    train = (direction, r.data[kind].length_m, o.leaves_lab)
    stops: list[Stop] = []
    for i, item in enumerate(o.stops):
        here = f"{place}.stops[{i}]"
        last, starts_here = i == len(o.stops) - 1, i == 0 and o.enters is None
        stop = _stop(r, item, here, train, last, starts_here)
        if stops:
            before = stops[-1]
            assert before.start_route is not None
            prev = r.line.station(before.station).route(before.start_route)
            reach = next_station(r.line, before.station, prev)
            if reach != stop.station:
                raise r.doc.fail(
                    f"{here}.station",
                    f"after station {before.station} a {direction} train reaches station "
                    f"{reach}, not {stop.station}",
                )
        stops.append(stop)
    return stops


def _appears_on(
    r: _TimetableRefs, place: str, direction: Direction, first: Stop, enters: Entry | None
) -> str:
    """The track circuit where the train is first seen: its entry's, or its first platform's."""
    st = r.line.station(first.station)
    if enters is None:
        return next(t.name for t in platform_circuits(st, first.track) if t.covers(first.stop_m))
    assert first.home_route is not None
    signal_at = st.signal(st.route(first.home_route).entry).position_m
    tc = r.tcs[enters.track_circuit]
    behind = tc.to_m <= signal_at if direction == "up" else tc.from_m >= signal_at
    if not behind:
        raise r.doc.fail(
            f"{place}.enters.track_circuit",
            f"{tc.name} is not on the approach to station {first.station} for an {direction} train",
        )
    return tc.name


def _train(r: _TimetableRefs, o: TimetableTrainShape, place: str) -> TimetableTrain:
    kind = str(o.train)
    if kind not in r.data:
        raise r.doc.fail(
            f"{place}.train",
            f"no train data {excerpt(kind)} under train_data ({', '.join(r.data) or 'none'})",
        )
    d = str(o.direction)
    if d not in DIRECTIONS:
        raise r.doc.fail(
            f"{place}.direction", f"must be one of {', '.join(DIRECTIONS)}, not {excerpt(d)}"
        )
    direction: Direction = "up" if d == "up" else "down"
    enters = None
    if o.enters is not None:
        where = str(o.enters.track_circuit)
        if where not in r.tcs:
            raise r.doc.fail(
                f"{place}.enters.track_circuit",
                f"no track circuit {excerpt(where)} on the line {r.line.name}",
            )
        enters = Entry(where, r.number(o.enters.at_s, f"{place}.enters.at_s"))
    stops = _stops(r, o, place, direction, kind)
    return TimetableTrain(
        id=str(o.id),
        direction=direction,
        data=r.data[kind],
        stops=tuple(stops),
        depart_s=r.number(o.depart_s, f"{place}.depart_s"),
        enters=enters,
        leaves_lab=o.leaves_lab,
        appears_on=_appears_on(r, place, direction, stops[0], enters),
    )


def load_timetable(path: str | Path, line: Line) -> Timetable:
    """Load and check a timetable against `line` (see the module docstring)."""
    path = Path(path)
    doc = _Doc(path)
    raw = convert(load_mapping(path, "timetable"), TimetableShape, path)
    if raw.line is not None:
        runs_on = (path.parent / str(raw.line)).resolve()
        if runs_on != Path(line.file).resolve():
            raise doc.fail("line", f"the timetable runs on {runs_on}, not on {line.file}")
    r = _TimetableRefs(doc, line, {})
    r.data = _train_data(doc, r, raw.train_data)
    trains = [_train(r, o, f"trains[{i}]") for i, o in enumerate(raw.trains)]
    if not trains:
        raise doc.fail("trains", "a timetable runs one train at least")
    ids = [t.id for t in trains]
    for i, train_id in enumerate(ids):
        if ids.index(train_id) != i:
            raise doc.fail(
                f"trains[{i}].id",
                f"duplicate train {excerpt(train_id)} (also trains[{ids.index(train_id)}])",
            )
    return Timetable(str(raw.timetable), str(path), tuple(trains))
