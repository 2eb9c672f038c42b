"""Load and schema-check station and line YAML (SPEC §6.2, §9: one clear message per bad file).

Every problem raises `ConfigError(file, place, problem)` where `place` is a key path such as
`routes[3].points[0].point`. Checks: missing keys, wrong types, duplicate names (across the whole
line for track circuits), unknown references (track circuits, points, signals, routes), route
sections that disagree with the route, conflicts that are not mutual, and routes that share a
track circuit or point without being declared conflicting.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

from ktcs_bench.datafiles import data_dir, load_mapping
from ktcs_bench.errors import ConfigError, excerpt
from ktcs_bench.station.model import (
    ASPECT_ORDER,
    DIRECTIONS,
    POINT_POSITIONS,
    SIGNAL_KINDS,
    Direction,
    Gradient,
    Interval,
    Line,
    Point,
    PointPosition,
    PointSetting,
    Route,
    Signal,
    SpeedCode,
    SpeedLimit,
    Station,
    TrackCircuit,
)

T = TypeVar("T")

DEFAULT_LINE = "lines/reference.yaml"


class _Doc:
    """Typed access to one parsed YAML document, raising ConfigError with the key path."""

    def __init__(self, file: str | Path) -> None:
        self.file = str(file)

    def fail(self, place: str, problem: str) -> ConfigError:
        return ConfigError(self.file, place, problem)

    def mapping(self, value: object, place: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(place, f"must be a mapping, not {_kind(value)}")
        return value

    def get(self, obj: dict[str, Any], key: str, place: str) -> object:
        if key not in obj:
            raise self.fail(_join(place, key), "missing key")
        return obj[key]

    def string(self, obj: dict[str, Any], key: str, place: str, default: str | None = None) -> str:
        if key not in obj and default is not None:
            return default
        value = self.get(obj, key, place)
        if isinstance(value, bool) or not isinstance(value, (str, int)):
            raise self.fail(_join(place, key), f"must be a string, not {_kind(value)}")
        return str(value)

    def number(
        self, obj: dict[str, Any], key: str, place: str, default: float | None = None
    ) -> float:
        if key not in obj and default is not None:
            return default
        value = self.get(obj, key, place)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(_join(place, key), f"must be a number, not {_kind(value)}")
        return float(value)

    def integer(self, obj: dict[str, Any], key: str, place: str) -> int:
        value = self.get(obj, key, place)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(_join(place, key), f"must be an integer, not {_kind(value)}")
        return value

    def items(
        self, obj: dict[str, Any], key: str, place: str, optional: bool = False
    ) -> list[object]:
        if optional and key not in obj:
            return []
        value = self.get(obj, key, place)
        if value is None and optional:
            return []
        if not isinstance(value, list):
            raise self.fail(_join(place, key), f"must be a list, not {_kind(value)}")
        return value

    def strings(
        self, obj: dict[str, Any], key: str, place: str, optional: bool = False
    ) -> tuple[str, ...]:
        out: list[str] = []
        for i, v in enumerate(self.items(obj, key, place, optional)):
            if isinstance(v, bool) or not isinstance(v, (str, int)):
                raise self.fail(f"{_join(place, key)}[{i}]", f"must be a string, not {_kind(v)}")
            out.append(str(v))
        return tuple(out)

    def choice(
        self, obj: dict[str, Any], key: str, place: str, allowed: Iterable[str], default: str = ""
    ) -> str:
        value = self.string(obj, key, place, default or None)
        allowed = tuple(allowed)
        if value not in allowed:
            raise self.fail(
                _join(place, key), f"must be one of {', '.join(allowed)}, not {excerpt(value)}"
            )
        return value

    def list_of(
        self, obj: dict[str, Any], key: str, place: str, build: Callable[[dict[str, Any], str], T]
    ) -> list[T]:
        out: list[T] = []
        for i, item in enumerate(self.items(obj, key, place)):
            here = f"{_join(place, key)}[{i}]"
            out.append(build(self.mapping(item, here), here))
        return out

    def unique(self, names: list[str], place: str, what: str) -> None:
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in seen:
                raise self.fail(
                    f"{place}[{i}].name",
                    f"duplicate {what} {excerpt(name)} (also {place}[{seen[name]}])",
                )
            seen[name] = i


def _join(place: str, key: str) -> str:
    return f"{place}.{key}" if place else key


def _kind(value: object) -> str:
    return "nothing" if value is None else type(value).__name__


# ---------------------------------------------------------------------------------------------
# station files


def load_station(path: str | Path, external_track_circuits: Iterable[str] = ()) -> Station:
    """Load one station file; `external_track_circuits` are plain-line names approaches may use."""
    doc = _Doc(path)
    raw = load_mapping(path, "station")
    number = doc.integer(raw, "station", "")
    name = doc.string(raw, "name", "", f"Station {number}")
    tracks = doc.strings(raw, "tracks", "")

    def build_tc(o: dict[str, Any], place: str) -> TrackCircuit:
        nm = doc.string(o, "name", place)
        lo, hi = doc.number(o, "from_m", place), doc.number(o, "to_m", place)
        if hi <= lo:
            raise doc.fail(f"{place}.to_m", f"must be beyond from_m ({lo:g}), not {hi:g}")
        length = doc.number(o, "length_m", place, hi - lo)
        if length <= 0:
            raise doc.fail(f"{place}.length_m", "must be positive")
        on = doc.strings(o, "tracks", place, optional=True)
        for i, t in enumerate(on):
            if t not in tracks:
                raise doc.fail(
                    f"{place}.tracks[{i}]", f"unknown track {excerpt(t)} (tracks: {tracks})"
                )
        return TrackCircuit(nm, lo, hi, length, number, on)

    tcs = doc.list_of(raw, "track_circuits", "", build_tc)
    doc.unique([t.name for t in tcs], "track_circuits", "track circuit")
    tc_names = {t.name for t in tcs}
    approach_names = tc_names | set(external_track_circuits)

    def tc_ref(name: str, place: str, allowed: set[str] = tc_names) -> str:
        if name not in allowed:
            raise doc.fail(place, f"unknown track circuit {excerpt(name)}")
        return name

    def build_point(o: dict[str, Any], place: str) -> Point:
        nm = doc.string(o, "name", place)
        refs = doc.strings(o, "track_circuits", place)
        if not refs:
            raise doc.fail(f"{place}.track_circuits", "a point needs at least one track circuit")
        for i, r in enumerate(refs):
            tc_ref(r, f"{place}.track_circuits[{i}]")
        throw = doc.number(o, "throw_time_s", place, 4.0)
        if throw <= 0:
            raise doc.fail(f"{place}.throw_time_s", "must be positive")
        return Point(nm, refs, doc.number(o, "position_m", place), throw)

    points = doc.list_of(raw, "points", "", build_point)
    doc.unique([p.name for p in points], "points", "point")
    point_names = {p.name for p in points}

    def build_signal(o: dict[str, Any], place: str) -> Signal:
        nm = doc.string(o, "name", place)
        kind = doc.choice(o, "kind", place, SIGNAL_KINDS)
        direction: Direction = (
            "up" if doc.choice(o, "direction", place, DIRECTIONS) == "up" else "down"
        )
        aspects = doc.strings(o, "aspects", place, optional=True)
        for i, a in enumerate(aspects):
            if a not in ASPECT_ORDER:
                raise doc.fail(
                    f"{place}.aspects[{i}]", f"unknown aspect {excerpt(a)} ({ASPECT_ORDER})"
                )
        if kind != "marker" and "R" not in aspects:
            raise doc.fail(f"{place}.aspects", "a signal with lamps must be able to show R (stop)")
        if kind == "marker" and aspects:
            raise doc.fail(f"{place}.aspects", "a marker has no lamps")
        track = doc.string(o, "track", place) if "track" in o else None
        if track is not None and track not in tracks:
            raise doc.fail(f"{place}.track", f"unknown track {excerpt(track)}")
        return Signal(nm, kind, direction, doc.number(o, "position_m", place), aspects, track)

    signals = doc.list_of(raw, "signals", "", build_signal)
    doc.unique([s.name for s in signals], "signals", "signal")
    by_signal = {s.name: s for s in signals}

    def settings(o: dict[str, Any], key: str, place: str) -> tuple[PointSetting, ...]:
        out: list[PointSetting] = []
        for i, item in enumerate(doc.items(o, key, place, optional=True)):
            here = f"{_join(place, key)}[{i}]"
            m = doc.mapping(item, here)
            pt = doc.string(m, "point", here)
            if pt not in point_names:
                raise doc.fail(f"{here}.point", f"unknown point {excerpt(pt)}")
            pos: PointPosition = (
                "normal"
                if doc.choice(m, "position", here, POINT_POSITIONS) == "normal"
                else "reverse"
            )
            out.append(PointSetting(pt, pos))
        return tuple(out)

    def build_route(o: dict[str, Any], place: str) -> Route:
        nm = doc.string(o, "name", place)
        entry = doc.string(o, "entry", place)
        exit_ = doc.string(o, "exit", place)
        for key, sig in (("entry", entry), ("exit", exit_)):
            if sig not in by_signal:
                raise doc.fail(f"{place}.{key}", f"unknown signal {excerpt(sig)}")
        if not by_signal[entry].has_lamps:
            raise doc.fail(
                f"{place}.entry", f"signal {excerpt(entry)} is a marker and cannot start a route"
            )
        direction = by_signal[entry].direction
        if by_signal[exit_].direction != direction:
            raise doc.fail(
                f"{place}.exit",
                f"signal {excerpt(exit_)} faces the other way from {excerpt(entry)}",
            )
        pts = settings(o, "points", place)
        route_tcs = doc.strings(o, "track_circuits", place)
        if not route_tcs:
            raise doc.fail(f"{place}.track_circuits", "a route needs at least one track circuit")
        for i, t in enumerate(route_tcs):
            tc_ref(t, f"{place}.track_circuits[{i}]")
        ov_tcs: tuple[str, ...] = ()
        ov_pts: tuple[PointSetting, ...] = ()
        if o.get("overlap") is not None:
            ov = doc.mapping(o["overlap"], f"{place}.overlap")
            ov_tcs = doc.strings(ov, "track_circuits", f"{place}.overlap")
            for i, t in enumerate(ov_tcs):
                tc_ref(t, f"{place}.overlap.track_circuits[{i}]")
            ov_pts = settings(ov, "points", f"{place}.overlap")
        for key, group, where in (("points", pts, route_tcs), ("overlap.points", ov_pts, ov_tcs)):
            for i, s in enumerate(group):
                own = next(p for p in points if p.name == s.point)
                if not set(own.track_circuits) & set(where):
                    raise doc.fail(
                        f"{place}.{key}[{i}].point",
                        f"point {excerpt(s.point)} lies in {', '.join(own.track_circuits)}, "
                        f"which is not among the track circuits it is listed with",
                    )
        seen_pts = [s.point for s in pts + ov_pts]
        for i, p in enumerate(seen_pts):
            if seen_pts.index(p) != i:
                raise doc.fail(f"{place}.points", f"point {excerpt(p)} is listed twice")
        approach = doc.strings(o, "approach", place)
        for i, t in enumerate(approach):
            tc_ref(t, f"{place}.approach[{i}]", approach_names)
        sections: list[tuple[str, ...]] = []
        raw_sections = doc.items(o, "release_sections", place, optional=True)
        if raw_sections:
            for i, sec in enumerate(raw_sections):
                here = f"{place}.release_sections[{i}]"
                if not isinstance(sec, list) or not sec:
                    raise doc.fail(here, "must be a non-empty list of track circuits")
                sections.append(tuple(str(t) for t in sec))
            flat = tuple(t for sec in sections for t in sec)
            if flat != route_tcs:
                raise doc.fail(
                    f"{place}.release_sections",
                    f"must list the route's track circuits in order {list(route_tcs)}, "
                    f"not {list(flat)}",
                )
        else:
            sections = [(t,) for t in route_tcs]
        aspect = doc.string(o, "aspect", place, "G" if by_signal[entry].kind != "shunt" else "W")
        if aspect not in by_signal[entry].aspects or aspect == "R":
            raise doc.fail(
                f"{place}.aspect",
                f"{excerpt(aspect)} is not a proceed aspect of signal {excerpt(entry)} {by_signal[entry].aspects}",
            )
        limit = doc.number(o, "speed_limit_kmh", place) if "speed_limit_kmh" in o else None
        return Route(
            name=nm,
            entry=entry,
            exit=exit_,
            direction=direction,
            points=pts,
            track_circuits=route_tcs,
            overlap_track_circuits=ov_tcs,
            overlap_points=ov_pts,
            conflicts=doc.strings(o, "conflicts", place, optional=True),
            approach=approach,
            release_sections=tuple(sections),
            aspect=aspect,
            approach_release_s=doc.number(o, "approach_release_s", place, 90.0),
            overlap_release_s=doc.number(o, "overlap_release_s", place, 30.0),
            speed_limit_kmh=limit,
        )

    routes = doc.list_of(raw, "routes", "", build_route)
    doc.unique([r.name for r in routes], "routes", "route")
    _check_conflicts(doc, routes, {p.name: p for p in points})
    return Station(
        number, name, str(path), tracks, tuple(tcs), tuple(points), tuple(signals), tuple(routes)
    )


def onward(first: Route, then: Route) -> bool:
    """`then` starts at `first`'s exit and shares with it only `first`'s overlap, set alike.

    Such routes are not conflicting: `then` takes the overlap over (a train running through).
    """
    if first.exit != then.entry:
        return False
    overlap = set(first.overlap_track_circuits) | {s.point for s in first.overlap_points}
    theirs = set(then.all_track_circuits) | {s.point for s in then.all_points}
    mine = set(first.all_track_circuits) | {s.point for s in first.all_points}
    if not (mine & theirs) <= overlap:
        return False
    want = {s.point: s.position for s in first.overlap_points}
    return all(want[s.point] == s.position for s in then.all_points if s.point in want)


def _check_conflicts(doc: _Doc, routes: list[Route], points: dict[str, Point]) -> None:
    index = {r.name: i for i, r in enumerate(routes)}
    for i, r in enumerate(routes):
        for j, c in enumerate(r.conflicts):
            place = f"routes[{i}].conflicts[{j}]"
            if c not in index:
                raise doc.fail(place, f"unknown route {excerpt(c)}")
            if c == r.name:
                raise doc.fail(place, "a route cannot conflict with itself")
            if r.name not in routes[index[c]].conflicts:
                raise doc.fail(
                    place, f"route {excerpt(c)} does not list {excerpt(r.name)} back as conflicting"
                )
    for i, r in enumerate(routes):
        mine = set(r.all_track_circuits) | {s.point for s in r.all_points}
        for other in routes[i + 1 :]:
            theirs = set(other.all_track_circuits) | {s.point for s in other.all_points}
            shared = sorted(mine & theirs)
            if r.entry == other.entry:
                shared.append(f"entry signal {r.entry}")
            if (
                shared
                and not (onward(r, other) or onward(other, r))
                and other.name not in r.conflicts
            ):
                raise doc.fail(
                    f"routes[{i}].conflicts",
                    f"route {excerpt(r.name)} shares {', '.join(shared)} with route {excerpt(other.name)} "
                    "but does not list it as conflicting",
                )


# ---------------------------------------------------------------------------------------------
# the line file


def default_line_path() -> Path:
    return data_dir("emulators") / DEFAULT_LINE


_CACHED_LINES = 8  # lines a process keeps (a device loads one; a test run loads many)
_lines: dict[Path, tuple[tuple[tuple[Path, bytes | None], ...], Line]] = {}


def _digest(path: Path) -> bytes | None:
    """What `path` holds, as a digest (None: it cannot be read)."""
    try:
        return hashlib.blake2b(path.read_bytes(), digest_size=16).digest()
    except OSError:
        return None


def load_line(path: str | Path | None = None) -> Line:
    """Load the line file and every station it names (default: the shipped reference line).

    Loaded once a process: a second call for the same file returns the same (frozen) Line as long
    as the line file and every station file still hold what they held -- compared by content, not
    by modification time, which a file rewritten within one clock tick would keep."""
    path = Path(path) if path is not None else default_line_path()
    key = path.resolve()
    cached = _lines.get(key)
    if cached is not None and all(_digest(f) == d for f, d in cached[0]):
        return cached[1]
    read: list[tuple[Path, bytes | None]] = []
    line = _read_line(path, read)
    _lines.pop(key, None)
    while len(_lines) >= _CACHED_LINES:
        del _lines[next(iter(_lines))]
    _lines[key] = (tuple(read), line)
    return line


def _read_line(path: Path, read: list[tuple[Path, bytes | None]]) -> Line:
    """`load_line` from the files, each file's digest appended to `read` before it is parsed."""
    read.append((path, _digest(path)))
    doc = _Doc(path)
    raw = load_mapping(path, "line")
    name = doc.string(raw, "line", "")
    start, end = doc.number(raw, "start_m", ""), doc.number(raw, "end_m", "")
    if end <= start:
        raise doc.fail("end_m", f"must be beyond start_m ({start:g})")

    station_files: list[tuple[int, Path, str]] = []
    for i, item in enumerate(doc.items(raw, "stations", "")):
        here = f"stations[{i}]"
        m = doc.mapping(item, here)
        number = doc.integer(m, "number", here)
        file = Path(os.path.normpath(path.parent / doc.string(m, "file", here)))
        station_files.append((number, file, here))
    numbers = [n for n, _, _ in station_files]
    for i, n in enumerate(numbers):
        if numbers.index(n) != i:
            raise doc.fail(f"stations[{i}].number", f"duplicate station {n}")

    def build_tc(o: dict[str, Any], place: str) -> TrackCircuit:
        nm = doc.string(o, "name", place)
        lo, hi = doc.number(o, "from_m", place), doc.number(o, "to_m", place)
        if hi <= lo:
            raise doc.fail(f"{place}.to_m", f"must be beyond from_m ({lo:g}), not {hi:g}")
        owner = doc.integer(o, "station", place)
        if owner not in numbers:
            raise doc.fail(f"{place}.station", f"unknown station {owner}")
        return TrackCircuit(nm, lo, hi, doc.number(o, "length_m", place, hi - lo), owner)

    plain = doc.list_of(raw, "track_circuits", "", build_tc)
    doc.unique([t.name for t in plain], "track_circuits", "track circuit")
    plain_names = {t.name for t in plain}

    stations: dict[int, Station] = {}
    for number, file, _place in station_files:
        read.append((file, _digest(file)))
        st = load_station(file, plain_names)
        if st.number != number:
            raise ConfigError(file, "station", f"is {st.number}, but {path} lists it as {number}")
        stations[number] = st
    owner_of = {t.name: f"track_circuits ({path.name})" for t in plain}
    for st in stations.values():
        for i, t in enumerate(st.track_circuits):
            if t.name in owner_of:
                raise ConfigError(
                    st.file,
                    f"track_circuits[{i}].name",
                    f"duplicate track circuit {excerpt(t.name)} (also in {owner_of[t.name]})",
                )
            owner_of[t.name] = st.file

    owned = {t.name: t.station for t in plain}
    for st in stations.values():
        for i, r in enumerate(st.routes):
            for j, tc in enumerate(r.approach):
                if tc in owned and owned[tc] != st.number:
                    raise ConfigError(
                        st.file,
                        f"routes[{i}].approach[{j}]",
                        f"track circuit {excerpt(tc)} belongs to station {owned[tc]}, not {st.number}",
                    )

    def build_interval(o: dict[str, Any], place: str) -> Interval:
        nm = doc.string(o, "name", place)
        west, east = doc.integer(o, "west", place), doc.integer(o, "east", place)
        boundary = bool(o.get("boundary", False))
        for key, n in (("west", west), ("east", east)):
            if n not in numbers and not boundary:
                raise doc.fail(f"{place}.{key}", f"unknown station {n} (not a boundary interval)")
        refs = doc.strings(o, "track_circuits", place)
        for i, t in enumerate(refs):
            if t not in plain_names:
                raise doc.fail(
                    f"{place}.track_circuits[{i}]", f"unknown track circuit {excerpt(t)}"
                )
        lo, hi = doc.number(o, "from_m", place), doc.number(o, "to_m", place)
        d = doc.choice(o, "default_direction", place, DIRECTIONS, "up")
        return Interval(nm, west, east, lo, hi, refs, "up" if d == "up" else "down", boundary)

    intervals = doc.list_of(raw, "intervals", "", build_interval)
    doc.unique([iv.name for iv in intervals], "intervals", "interval")

    def build_grad(o: dict[str, Any], place: str) -> Gradient:
        return Gradient(
            doc.number(o, "from_m", place),
            doc.number(o, "to_m", place),
            doc.number(o, "permille", place),
        )

    def build_limit(o: dict[str, Any], place: str) -> SpeedLimit:
        kmh = doc.number(o, "kmh", place)
        if kmh <= 0:
            raise doc.fail(f"{place}.kmh", "must be positive")
        return SpeedLimit(doc.number(o, "from_m", place), doc.number(o, "to_m", place), kmh)

    gradients = doc.list_of(raw, "gradients", "", build_grad)
    limits = doc.list_of(raw, "speed_limits", "", build_limit)
    spans: list[tuple[str, float, float]] = [("gradients", g.from_m, g.to_m) for g in gradients]
    spans += [("speed_limits", s.from_m, s.to_m) for s in limits]
    counts: dict[str, int] = {}
    for key, lo, hi in spans:
        i = counts[key] = counts.get(key, -1) + 1
        if hi <= lo:
            raise doc.fail(f"{key}[{i}].to_m", f"must be beyond from_m ({lo:g})")

    atc = doc.mapping(doc.get(raw, "atc", ""), "atc")

    def build_code(o: dict[str, Any], place: str) -> SpeedCode:
        kmh = doc.number(o, "kmh", place)
        if kmh < 0:
            raise doc.fail(f"{place}.kmh", "must not be negative")
        return SpeedCode(doc.integer(o, "code", place), kmh)

    codes = doc.list_of(atc, "codes", "atc", build_code)
    code_numbers = [c.code for c in codes]
    for i, c in enumerate(code_numbers):
        if code_numbers.index(c) != i:
            raise doc.fail(f"atc.codes[{i}].code", f"duplicate code {c}")
    if not any(c.kmh == 0 for c in codes):
        raise doc.fail("atc.codes", "needs a stop code (kmh: 0), the most restrictive code")
    brake = doc.number(atc, "service_brake_mps2", "atc", 0.5)
    if brake <= 0:
        raise doc.fail("atc.service_brake_mps2", "must be positive")
    tags = doc.mapping(raw.get("tags", {}), "tags")
    return Line(
        name=name,
        file=str(path),
        start_m=start,
        end_m=end,
        stations=stations,
        track_circuits=tuple(plain),
        intervals=tuple(intervals),
        gradients=tuple(gradients),
        speed_limits=tuple(limits),
        speed_codes=tuple(sorted(codes, key=lambda c: (c.kmh, c.code))),
        service_brake_mps2=brake,
        tag_spacing_m=doc.number(tags, "spacing_m", "tags", 100.0),
    )
