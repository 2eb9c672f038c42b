"""Timetables: which trains run, with what train data, where they start, and where they stop.

A timetable file (`emulators/timetables/*.yaml`, and the one `ktcs-bench line generate` writes;
format in docs/ars.md) names the line it runs on (`line`, optional, relative to the file), its
train data by name (`train_data`: length, top speed, traction and brake rates -- seed 001
Table 1), and its trains. A train has an id, its data (`train`), a direction, and its stops in
running order: station, platform track, where its front stops (`stop_m`) and how long it stands
there (`dwell_s`). It starts standing at its first stop and leaves it at `depart_s` -- or, with
`enters: {track_circuit, at_s}`, it comes onto the line at that track circuit, not before `at_s`,
and runs to its first stop. It ends at its last stop unless it `leaves_lab`. Times are seconds
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


def load_timetable(path: str | Path, line: Line) -> Timetable:
    """Load and check a timetable against `line` (see the module docstring)."""
    path = Path(path)
    doc = _Doc(path)
    raw = load_mapping(path, "timetable")
    name = doc.string(raw, "timetable", "")
    if "line" in raw:
        runs_on = (path.parent / doc.string(raw, "line", "")).resolve()
        if runs_on != Path(line.file).resolve():
            raise doc.fail("line", f"the timetable runs on {runs_on}, not on {line.file}")
    tcs = {t.name: t for t in line.all_track_circuits()}

    def number(o: dict[str, Any], key: str, place: str, default: float | None = None) -> float:
        value = doc.number(o, key, place, default)
        if not math.isfinite(value) or value < 0:
            raise doc.fail(
                f"{place}.{key}", f"must be a finite number >= 0, not {excerpt(o.get(key))}"
            )
        return value

    data: dict[str, TrainData] = {}
    table = doc.mapping(doc.get(raw, "train_data", ""), "train_data")
    for key, item in table.items():
        here = f"train_data.{key}"
        o = doc.mapping(item, here)
        values = [number(o, k, here) for k in TRAIN_DATA_KEYS]
        for k, v in zip(TRAIN_DATA_KEYS, values, strict=True):
            if v <= 0:
                raise doc.fail(f"{here}.{k}", "must be positive")
        data[str(key)] = TrainData(str(key), *values)

    def build_stop(
        o: dict[str, Any],
        here: str,
        direction: Direction,
        length: float,
        i: int,
        n: int,
        leaves: bool,
        starts_here: bool,
    ) -> Stop:
        number_ = doc.integer(o, "station", here)
        if number_ not in line.stations:
            raise doc.fail(f"{here}.station", f"station {number_} is not on the line {line.name}")
        st = line.station(number_)
        track = doc.string(o, "track", here)
        if track not in st.tracks:
            raise doc.fail(
                f"{here}.track",
                f"station {number_} has no track {excerpt(track)} (tracks: {', '.join(st.tracks)})",
            )
        stop_m = doc.number(o, "stop_m", here)
        rear = stop_m - length if direction == "up" else stop_m + length
        platform = platform_circuits(st, track)
        if not any(t.covers(stop_m) and t.covers(rear) for t in platform):
            where = ", ".join(f"{t.name} ({t.from_m:g}-{t.to_m:g} m)" for t in platform)
            raise doc.fail(
                f"{here}.stop_m",
                f"a {length:g} m train stopping at {stop_m:g} m "
                f"does not stand wholly on track {track}'s circuit {where or '(none)'}",
            )
        last = i == n - 1
        start = start_route(line, st, direction, track)
        if start is None and (not last or leaves):
            raise doc.fail(
                f"{here}.track", f"no {direction} route out of station {number_} from track {track}"
            )
        home = None if starts_here else home_route(st, direction, track)
        if home is None and not starts_here:
            raise doc.fail(
                f"{here}.track",
                f"no {direction} route from the home signal of "
                f"station {number_} into track {track}",
            )
        return Stop(
            number_,
            track,
            stop_m,
            number(o, "dwell_s", here, 0.0),
            None if home is None else home.name,
            start.name if start is not None and (not last or leaves) else None,
        )

    def build_train(o: dict[str, Any], place: str) -> TimetableTrain:
        train_id = doc.string(o, "id", place)
        kind = doc.string(o, "train", place)
        if kind not in data:
            raise doc.fail(
                f"{place}.train",
                f"no train data {excerpt(kind)} under train_data ({', '.join(data) or 'none'})",
            )
        direction: Direction = (
            "up" if doc.choice(o, "direction", place, DIRECTIONS) == "up" else "down"
        )
        enters = None
        if "enters" in o:
            e = doc.mapping(o["enters"], f"{place}.enters")
            where = doc.string(e, "track_circuit", f"{place}.enters")
            if where not in tcs:
                raise doc.fail(
                    f"{place}.enters.track_circuit",
                    f"no track circuit {excerpt(where)} on the line {line.name}",
                )
            enters = Entry(where, number(e, "at_s", f"{place}.enters", 0.0))
        leaves = o.get("leaves_lab", False)
        if not isinstance(leaves, bool):
            raise doc.fail(f"{place}.leaves_lab", f"must be true or false, not {excerpt(leaves)}")
        raw_stops = doc.items(o, "stops", place)
        if not raw_stops:
            raise doc.fail(f"{place}.stops", "a train stops at one station at least")
        stops: list[Stop] = []
        length = data[kind].length_m
        for i, item in enumerate(raw_stops):
            here = f"{place}.stops[{i}]"
            stop = build_stop(
                doc.mapping(item, here),
                here,
                direction,
                length,
                i,
                len(raw_stops),
                leaves,
                i == 0 and enters is None,
            )
            if stops:
                before = stops[-1]
                assert before.start_route is not None
                prev = line.station(before.station).route(before.start_route)
                reach = next_station(line, before.station, prev)
                if reach != stop.station:
                    raise doc.fail(
                        f"{here}.station",
                        f"after station {before.station} a "
                        f"{direction} train reaches station {reach}, not "
                        f"{stop.station}",
                    )
            stops.append(stop)
        first = stops[0]
        st = line.station(first.station)
        if enters is None:
            appears_on = next(
                t.name for t in platform_circuits(st, first.track) if t.covers(first.stop_m)
            )
        else:
            assert first.home_route is not None
            signal_at = st.signal(st.route(first.home_route).entry).position_m
            tc = tcs[enters.track_circuit]
            behind = tc.to_m <= signal_at if direction == "up" else tc.from_m >= signal_at
            if not behind:
                raise doc.fail(
                    f"{place}.enters.track_circuit",
                    f"{tc.name} is not on the "
                    f"approach to station {first.station} for an {direction} train",
                )
            appears_on = tc.name
        return TimetableTrain(
            id=train_id,
            direction=direction,
            data=data[kind],
            stops=tuple(stops),
            depart_s=number(o, "depart_s", place, 0.0),
            enters=enters,
            leaves_lab=leaves,
            appears_on=appears_on,
        )

    trains = doc.list_of(raw, "trains", "", build_train)
    if not trains:
        raise doc.fail("trains", "a timetable runs one train at least")
    ids = [t.id for t in trains]
    for i, train_id in enumerate(ids):
        if ids.index(train_id) != i:
            raise doc.fail(
                f"trains[{i}].id",
                f"duplicate train {excerpt(train_id)} (also trains[{ids.index(train_id)}])",
            )
    return Timetable(name, str(path), tuple(trains))
