"""Load and schema-check station and line YAML (SPEC §6.2, §9: one clear message per bad file).

Every problem raises `ConfigError(file, place, problem)` where `place` is a key path such as
`routes[3].points[0].point`. The files' shapes -- keys, types, defaults -- are declared in
`shapes.py` and converted by `schema.convert` (missing, unknown and mistyped keys); then checked
here: duplicate names (across the whole line for track circuits), unknown references (track circuits, points, signals, routes), route
sections that disagree with the route, conflicts that are not mutual, and routes that share a
track circuit or point without being declared conflicting.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

from ktcs_bench.datafiles import data_dir, load_mapping
from ktcs_bench.errors import ConfigError, excerpt
from ktcs_bench.schema import convert, located
from ktcs_bench.station.geometry import GeometryError, walk_route
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
from ktcs_bench.station.shapes import (
    AtcShape,
    IntervalShape,
    LineShape,
    LineTrackCircuitShape,
    PointShape,
    RouteShape,
    SettingShape,
    SignalShape,
    StationShape,
    TrackCircuitShape,
)

DEFAULT_LINE = "lines/reference.yaml"


class _Doc:
    """The checks of one file's converted shape: each mistake a ConfigError with the key path."""

    def __init__(self, file: str | Path) -> None:
        self.file = str(file)

    def fail(self, place: str, problem: str) -> ConfigError:
        return located(self.file, place, problem)

    def unique(self, names: list[str], place: str, what: str) -> None:
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in seen:
                raise self.fail(
                    f"{place}[{i}].name",
                    f"duplicate {what} {excerpt(name)} (also {place}[{seen[name]}])",
                )
            seen[name] = i


# ---------------------------------------------------------------------------------------------
# station files


class _StationRefs:
    """What the parts of one station file may refer to, filled in as they are read."""

    def __init__(self, doc: _Doc, number: int, tracks: tuple[str, ...]) -> None:
        self.doc = doc
        self.number = number
        self.tracks = tracks
        self.tc_names: set[str] = set()
        self.approach_names: set[str] = set()
        self.points: dict[str, Point] = {}
        self.signals: dict[str, Signal] = {}

    def tc(self, name: str, place: str, allowed: set[str] | None = None) -> str:
        if name not in (self.tc_names if allowed is None else allowed):
            raise self.doc.fail(place, f"unknown track circuit {excerpt(name)}")
        return name

    def choice(self, value: str, place: str, allowed: Iterable[str]) -> str:
        allowed = tuple(allowed)
        if value not in allowed:
            raise self.doc.fail(place, f"must be one of {', '.join(allowed)}, not {excerpt(value)}")
        return value


def _names(values: tuple[str | int, ...] | None) -> tuple[str, ...]:
    return tuple(str(v) for v in values or ())


def _track_circuit(s: _StationRefs, o: TrackCircuitShape, place: str) -> TrackCircuit:
    lo, hi = o.from_m, o.to_m
    if hi <= lo:
        raise s.doc.fail(f"{place}.to_m", f"must be beyond from_m ({lo:g}), not {hi:g}")
    length = hi - lo if o.length_m is None else o.length_m
    if length <= 0:
        raise s.doc.fail(f"{place}.length_m", "must be positive")
    on = _names(o.tracks)
    for i, t in enumerate(on):
        if t not in s.tracks:
            raise s.doc.fail(
                f"{place}.tracks[{i}]", f"unknown track {excerpt(t)} (tracks: {s.tracks})"
            )
    return TrackCircuit(str(o.name), lo, hi, length, s.number, on)


def _point(s: _StationRefs, o: PointShape, place: str) -> Point:
    refs = _names(o.track_circuits)
    if not refs:
        raise s.doc.fail(f"{place}.track_circuits", "a point needs at least one track circuit")
    for i, r in enumerate(refs):
        s.tc(r, f"{place}.track_circuits[{i}]")
    if o.throw_time_s <= 0:
        raise s.doc.fail(f"{place}.throw_time_s", "must be positive")
    up = s.choice(str(o.facing), f"{place}.facing", DIRECTIONS) == "up"
    facing: Direction = "up" if up else "down"
    legs: dict[str, str] = {}
    for key, value in (("normal", o.normal), ("reverse", o.reverse), ("toe", o.toe)):
        if value is None:
            continue
        legs[key] = str(value)
        if legs[key] not in s.tracks:
            raise s.doc.fail(
                f"{place}.{key}", f"unknown track {excerpt(legs[key])} (tracks: {s.tracks})"
            )
    if legs["normal"] == legs["reverse"]:
        raise s.doc.fail(f"{place}.reverse", "the reverse leg leads to the normal leg's track")
    return Point(
        str(o.name), refs, o.position_m, facing=facing, normal=legs["normal"],
        reverse=legs["reverse"], toe=legs.get("toe"), throw_time_s=o.throw_time_s,
    )  # fmt: skip


def _signal(s: _StationRefs, o: SignalShape, place: str) -> Signal:
    kind = s.choice(str(o.kind), f"{place}.kind", SIGNAL_KINDS)
    up = s.choice(str(o.direction), f"{place}.direction", DIRECTIONS) == "up"
    aspects = _names(o.aspects)
    for i, a in enumerate(aspects):
        if a not in ASPECT_ORDER:
            raise s.doc.fail(
                f"{place}.aspects[{i}]", f"unknown aspect {excerpt(a)} ({ASPECT_ORDER})"
            )
    if kind != "marker" and "R" not in aspects:
        raise s.doc.fail(f"{place}.aspects", "a signal with lamps must be able to show R (stop)")
    if kind == "marker" and aspects:
        raise s.doc.fail(f"{place}.aspects", "a marker has no lamps")
    track = None if o.track is None else str(o.track)
    if track is not None and track not in s.tracks:
        raise s.doc.fail(f"{place}.track", f"unknown track {excerpt(track)}")
    direction: Direction = "up" if up else "down"
    return Signal(str(o.name), kind, direction, o.position_m, aspects, track)


def _settings(
    s: _StationRefs, items: tuple[SettingShape, ...] | None, place: str
) -> tuple[PointSetting, ...]:
    out: list[PointSetting] = []
    for i, m in enumerate(items or ()):
        here = f"{place}[{i}]"
        pt = str(m.point)
        if pt not in s.points:
            raise s.doc.fail(f"{here}.point", f"unknown point {excerpt(pt)}")
        normal = s.choice(str(m.position), f"{here}.position", POINT_POSITIONS) == "normal"
        position: PointPosition = "normal" if normal else "reverse"
        out.append(PointSetting(pt, position))
    return tuple(out)


def _route_ends(s: _StationRefs, o: RouteShape, place: str) -> tuple[str, str, Direction]:
    entry, exit_ = str(o.entry), str(o.exit)
    for key, sig in (("entry", entry), ("exit", exit_)):
        if sig not in s.signals:
            raise s.doc.fail(f"{place}.{key}", f"unknown signal {excerpt(sig)}")
    if not s.signals[entry].has_lamps:
        raise s.doc.fail(
            f"{place}.entry", f"signal {excerpt(entry)} is a marker and cannot start a route"
        )
    direction = s.signals[entry].direction
    if s.signals[exit_].direction != direction:
        raise s.doc.fail(
            f"{place}.exit", f"signal {excerpt(exit_)} faces the other way from {excerpt(entry)}"
        )
    return entry, exit_, direction


def _route_points(
    s: _StationRefs, o: RouteShape, place: str, route_tcs: tuple[str, ...]
) -> tuple[tuple[PointSetting, ...], tuple[str, ...], tuple[PointSetting, ...]]:
    """The route's point settings, its overlap's track circuits and point settings."""
    pts = _settings(s, o.points, f"{place}.points")
    ov_tcs: tuple[str, ...] = ()
    ov_pts: tuple[PointSetting, ...] = ()
    if o.overlap is not None:
        ov_tcs = _names(o.overlap.track_circuits)
        for i, t in enumerate(ov_tcs):
            s.tc(t, f"{place}.overlap.track_circuits[{i}]")
        ov_pts = _settings(s, o.overlap.points, f"{place}.overlap.points")
    for key, group, where in (("points", pts, route_tcs), ("overlap.points", ov_pts, ov_tcs)):
        for i, setting in enumerate(group):
            own = s.points[setting.point]
            if not set(own.track_circuits) & set(where):
                raise s.doc.fail(
                    f"{place}.{key}[{i}].point",
                    f"point {excerpt(setting.point)} lies in {', '.join(own.track_circuits)}, "
                    f"which is not among the track circuits it is listed with",
                )
    seen_pts = [p.point for p in pts + ov_pts]
    for i, p in enumerate(seen_pts):
        if seen_pts.index(p) != i:
            raise s.doc.fail(f"{place}.points", f"point {excerpt(p)} is listed twice")
    return pts, ov_tcs, ov_pts


def _release_sections(
    s: _StationRefs, o: RouteShape, place: str, route_tcs: tuple[str, ...]
) -> tuple[tuple[str, ...], ...]:
    if not o.release_sections:
        return tuple((t,) for t in route_tcs)
    sections: list[tuple[str, ...]] = []
    for i, sec in enumerate(o.release_sections):
        if not isinstance(sec, list) or not sec:
            raise s.doc.fail(
                f"{place}.release_sections[{i}]", "must be a non-empty list of track circuits"
            )
        sections.append(tuple(str(t) for t in sec))
    flat = tuple(t for sec in sections for t in sec)
    if flat != route_tcs:
        raise s.doc.fail(
            f"{place}.release_sections",
            f"must list the route's track circuits in order {list(route_tcs)}, not {list(flat)}",
        )
    return tuple(sections)


def _route(s: _StationRefs, o: RouteShape, place: str) -> Route:
    entry, exit_, direction = _route_ends(s, o, place)
    route_tcs = _names(o.track_circuits)
    if not route_tcs:
        raise s.doc.fail(f"{place}.track_circuits", "a route needs at least one track circuit")
    for i, t in enumerate(route_tcs):
        s.tc(t, f"{place}.track_circuits[{i}]")
    pts, ov_tcs, ov_pts = _route_points(s, o, place, route_tcs)
    approach = _names(o.approach)
    for i, t in enumerate(approach):
        s.tc(t, f"{place}.approach[{i}]", s.approach_names)
    sections = _release_sections(s, o, place, route_tcs)
    signal = s.signals[entry]
    aspect = str(o.aspect) if o.aspect is not None else "G" if signal.kind != "shunt" else "W"
    if aspect not in signal.aspects or aspect == "R":
        raise s.doc.fail(
            f"{place}.aspect",
            f"{excerpt(aspect)} is not a proceed aspect of signal {excerpt(entry)} {signal.aspects}",
        )
    return Route(
        name=str(o.name),
        entry=entry,
        exit=exit_,
        direction=direction,
        points=pts,
        track_circuits=route_tcs,
        overlap_track_circuits=ov_tcs,
        overlap_points=ov_pts,
        conflicts=_names(o.conflicts),
        approach=approach,
        release_sections=sections,
        aspect=aspect,
        approach_release_s=o.approach_release_s,
        overlap_release_s=o.overlap_release_s,
        speed_limit_kmh=o.speed_limit_kmh,
    )


def load_station(path: str | Path, external_track_circuits: Iterable[str] = ()) -> Station:
    """Load one station file; `external_track_circuits` are plain-line names approaches may use."""
    doc = _Doc(path)
    raw = convert(load_mapping(path, "station"), StationShape, path)
    number = raw.station
    s = _StationRefs(doc, number, _names(raw.tracks))
    tcs = [_track_circuit(s, o, f"track_circuits[{i}]") for i, o in enumerate(raw.track_circuits)]
    doc.unique([t.name for t in tcs], "track_circuits", "track circuit")
    s.tc_names = {t.name for t in tcs}
    s.approach_names = s.tc_names | set(external_track_circuits)
    points = [_point(s, o, f"points[{i}]") for i, o in enumerate(raw.points)]
    doc.unique([p.name for p in points], "points", "point")
    s.points = {p.name: p for p in points}
    signals = [_signal(s, o, f"signals[{i}]") for i, o in enumerate(raw.signals)]
    doc.unique([g.name for g in signals], "signals", "signal")
    s.signals = {g.name: g for g in signals}
    routes = [_route(s, o, f"routes[{i}]") for i, o in enumerate(raw.routes)]
    doc.unique([r.name for r in routes], "routes", "route")
    _check_conflicts(doc, routes, s.points)
    name = str(raw.name) if raw.name is not None else f"Station {number}"
    station = Station(
        number, name, str(path), s.tracks, tuple(tcs), tuple(points), tuple(signals), tuple(routes)
    )
    for i, r in enumerate(routes):
        try:
            walk_route(station, r, f"routes[{i}]")
        except GeometryError as exc:
            raise doc.fail(exc.place, f"route {r.name}: {exc.problem}") from None
    return station


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
    raw = convert(load_mapping(path, "line"), LineShape, path)
    if raw.end_m <= raw.start_m:
        raise doc.fail("end_m", f"must be beyond start_m ({raw.start_m:g})")
    numbers = [s.number for s in raw.stations]
    for i, n in enumerate(numbers):
        if numbers.index(n) != i:
            raise doc.fail(f"stations[{i}].number", f"duplicate station {n}")
    plain = [_line_track_circuit(doc, o, f"track_circuits[{i}]", numbers)
             for i, o in enumerate(raw.track_circuits)]  # fmt: skip
    doc.unique([t.name for t in plain], "track_circuits", "track circuit")
    stations = _line_stations(path, raw, plain, read)
    plain_names = {t.name for t in plain}
    intervals = [_interval(doc, o, f"intervals[{i}]", numbers, plain_names)
                 for i, o in enumerate(raw.intervals)]  # fmt: skip
    doc.unique([iv.name for iv in intervals], "intervals", "interval")
    gradients = [Gradient(g.from_m, g.to_m, g.permille) for g in raw.gradients]
    limits = [SpeedLimit(s.from_m, s.to_m, s.kmh) for s in raw.speed_limits]
    for i, s in enumerate(raw.speed_limits):
        if s.kmh <= 0:
            raise doc.fail(f"speed_limits[{i}].kmh", "must be positive")
    spans: list[tuple[str, float, float]] = [("gradients", g.from_m, g.to_m) for g in gradients]
    spans += [("speed_limits", s.from_m, s.to_m) for s in limits]
    counts: dict[str, int] = {}
    for key, lo, hi in spans:
        i = counts[key] = counts.get(key, -1) + 1
        if hi <= lo:
            raise doc.fail(f"{key}[{i}].to_m", f"must be beyond from_m ({lo:g})")
    codes = _speed_codes(doc, raw.atc)
    return Line(
        name=str(raw.line),
        file=str(path),
        start_m=raw.start_m,
        end_m=raw.end_m,
        stations=stations,
        track_circuits=tuple(plain),
        intervals=tuple(intervals),
        gradients=tuple(gradients),
        speed_limits=tuple(limits),
        speed_codes=tuple(sorted(codes, key=lambda c: (c.kmh, c.code))),
        service_brake_mps2=raw.atc.service_brake_mps2,
        brake_build_up_s=raw.atc.brake_build_up_s,
        tag_spacing_m=raw.tags.spacing_m,
    )


def _line_track_circuit(
    doc: _Doc, o: LineTrackCircuitShape, place: str, numbers: list[int]
) -> TrackCircuit:
    """A plain-line track circuit (between stations, owned by one of them)."""
    lo, hi = o.from_m, o.to_m
    if hi <= lo:
        raise doc.fail(f"{place}.to_m", f"must be beyond from_m ({lo:g}), not {hi:g}")
    if o.station not in numbers:
        raise doc.fail(f"{place}.station", f"unknown station {o.station}")
    length = hi - lo if o.length_m is None else o.length_m
    return TrackCircuit(str(o.name), lo, hi, length, o.station)


def _line_stations(
    path: Path, raw: LineShape, plain: list[TrackCircuit], read: list[tuple[Path, bytes | None]]
) -> dict[int, Station]:
    """The stations the line names, each file loaded and checked against the line: its number,
    no track circuit twice on the line, approaches only over its own plain track circuits."""
    plain_names = {t.name for t in plain}
    stations: dict[int, Station] = {}
    for ref in raw.stations:
        file = Path(os.path.normpath(path.parent / str(ref.file)))
        read.append((file, _digest(file)))
        st = load_station(file, plain_names)
        if st.number != ref.number:
            raise ConfigError(
                file, "station", f"is {st.number}, but {path} lists it as {ref.number}"
            )
        stations[ref.number] = st
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
    return stations


def _interval(
    doc: _Doc, o: IntervalShape, place: str, numbers: list[int], plain_names: set[str]
) -> Interval:
    for key, n in (("west", o.west), ("east", o.east)):
        if n not in numbers and not o.boundary:
            raise doc.fail(f"{place}.{key}", f"unknown station {n} (not a boundary interval)")
    refs = _names(o.track_circuits)
    for i, t in enumerate(refs):
        if t not in plain_names:
            raise doc.fail(f"{place}.track_circuits[{i}]", f"unknown track circuit {excerpt(t)}")
    d = str(o.default_direction)
    if d not in DIRECTIONS:
        raise doc.fail(
            f"{place}.default_direction",
            f"must be one of {', '.join(DIRECTIONS)}, not {excerpt(d)}",
        )
    direction: Direction = "up" if d == "up" else "down"
    return Interval(str(o.name), o.west, o.east, o.from_m, o.to_m, refs, direction, o.boundary)


def _speed_codes(doc: _Doc, atc: AtcShape) -> list[SpeedCode]:
    for i, c in enumerate(atc.codes):
        if c.kmh < 0:
            raise doc.fail(f"atc.codes[{i}].kmh", "must not be negative")
    code_numbers = [c.code for c in atc.codes]
    for i, n in enumerate(code_numbers):
        if code_numbers.index(n) != i:
            raise doc.fail(f"atc.codes[{i}].code", f"duplicate code {n}")
    if not any(c.kmh == 0 for c in atc.codes):
        raise doc.fail("atc.codes", "needs a stop code (kmh: 0), the most restrictive code")
    if atc.service_brake_mps2 <= 0:
        raise doc.fail("atc.service_brake_mps2", "must be positive")
    if atc.brake_build_up_s < 0:
        raise doc.fail("atc.brake_build_up_s", "must not be negative")
    return [SpeedCode(c.code, c.kmh) for c in atc.codes]
