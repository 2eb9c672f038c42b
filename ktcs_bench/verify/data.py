"""Station data against the point geometry (SPEC §13, §6.7): what each route must hold, derived
from the path a train takes from its entry signal to its exit and on over its overlap.

The loader already refuses station files whose routes cannot be walked or whose conflicts are
not symmetric; these checks run on the loaded (or built) `Line` objects again, independently, and
also derive what the loader does not: each route's track circuits from the walk, flank protection
from the legs not taken, and conflicts from shared elements and opposing paths. Each finding names
the station, the route and the element.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any

from ktcs_bench.station.geometry import (
    GeometryError,
    LineGeometry,
    RouteWalk,
    Track,
    meets,
    walk_route,
    walked_track_circuits,
)
from ktcs_bench.station.loader import onward
from ktcs_bench.station.model import Line, Point, PointSetting, Route, Station


@dataclass(frozen=True, slots=True)
class Finding:
    """One fault in the data: `kind` is path, position, track_circuit, overlap, flank, conflict
    or release."""

    station: int
    route: str
    element: str
    kind: str
    text: str

    def as_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        return (
            f"station {self.station} route {self.route} [{self.kind}] {self.element}: {self.text}"
        )


@dataclass(frozen=True, slots=True)
class PointOnPath:
    """A point the walk runs over, the position the path needs, and the leg it does not take."""

    point: str
    position: str
    in_overlap: bool
    other_leg: Track
    upward: bool


def _walk(station: Station, route: Route) -> RouteWalk:
    return walk_route(station, route, f"route {route.name}")


def points_on_path(station: Station, route: Route) -> list[PointOnPath]:
    """The points of a route's walk (route, then overlap), in the order the train meets them."""
    upward = route.direction == "up"
    overlap = {s.point for s in route.overlap_points}
    want = {s.point: s.position for s in route.all_points}
    out = []
    for p in station.points:
        if p.name not in want:
            continue
        position = want[p.name]
        other = "reverse" if position == "normal" else "normal"
        out.append(PointOnPath(p.name, position, p.name in overlap, p.leg(other), upward))  # type: ignore[arg-type]
    key = {p.name: p.position_m for p in station.points}
    out.sort(key=lambda x: key[x.point], reverse=not upward)
    return out


def _runs_over_from(station: Station, route: Route, point: Point, leg: Track) -> bool:
    """`route`'s walk comes to `point` along the track `leg` (facing or trailing)."""
    try:
        walk = _walk(station, route)
    except GeometryError:
        return False
    upward = route.direction == "up"
    for lo, hi, track in walk.route + walk.overlap:
        if track == leg and point.position_m == (hi if upward else lo) and lo < hi:
            meeting = meets(point, track, upward)
            if meeting is not None and meeting != "toe":
                return True
    return False


def flank_routes(station: Station, route: Route) -> dict[str, list[str]]:
    """Point -> the routes that would bring a train over the leg of it that `route` does not
    take, towards the point: they must be held off (in conflict) while `route` is locked. A
    signal on that leg at stop is the flank protection; these are the routes that clear it."""
    out: dict[str, list[str]] = {}
    for pp in points_on_path(station, route):
        point = station.point(pp.point)
        if pp.other_leg is None:
            continue
        threats = []
        for q in station.routes:
            if q.name == route.name:
                continue
            if _runs_over_from(station, q, point, pp.other_leg):
                threats.append(q.name)
        if threats:
            out[pp.point] = sorted(threats)
    return out


def flank_signals(station: Station, route: Route) -> dict[str, list[str]]:
    """Point -> the signals whose routes `flank_routes` names (held at stop: the protection)."""
    routes = flank_routes(station, route)
    return {p: sorted({station.route(q).entry for q in qs}) for p, qs in routes.items()}


def _path_findings(station: Station, route: Route, exc: GeometryError) -> list[Finding]:
    """A route whose walk fails: name the point whose position (or absence) breaks it."""
    st, name = station.number, route.name
    m = re.search(r"point (\S+)", exc.problem)
    if m and "does not set it" in exc.problem:
        return [Finding(st, name, m.group(1), "overlap" if "overlap" in exc.place or _beyond_exit(
            station, route, m.group(1)) else "position", f"the path runs over point {m.group(1)} "
            "and the route does not set it")]  # fmt: skip
    # a point set wrong: the flip of one setting that makes the path whole names it
    for key in ("points", "overlap_points"):
        settings: tuple[PointSetting, ...] = getattr(route, key)
        for i, s in enumerate(settings):
            flipped = PointSetting(s.point, "reverse" if s.position == "normal" else "normal")
            changed: dict[str, Any] = {key: settings[:i] + (flipped,) + settings[i + 1 :]}
            trial = dataclasses.replace(route, **changed)
            try:
                _walk(station, trial)
            except GeometryError:
                continue
            return [Finding(st, name, s.point, "position",
                            f"set {s.position}; the path to exit {route.exit} needs it "
                            f"{flipped.position}")]  # fmt: skip
    element = m.group(1) if m else route.exit
    return [Finding(st, name, element, "path", exc.problem)]


def _beyond_exit(station: Station, route: Route, point: str) -> bool:
    p, exit_ = station.point(point), station.signal(route.exit)
    return (
        p.position_m > exit_.position_m
        if route.direction == "up"
        else p.position_m < exit_.position_m
    )


def check_route(
    line: Line, geometry: LineGeometry, station: Station, route: Route
) -> list[Finding]:
    """One route against its walk: path, point positions, track circuits, overlap, sections."""
    st, name = station.number, route.name
    try:
        walk = _walk(station, route)
    except GeometryError as exc:
        return _path_findings(station, route, exc)
    out: list[Finding] = []
    for key, stretches, listed in (
        ("track_circuit", walk.route, route.track_circuits),
        ("overlap", walk.overlap, route.overlap_track_circuits),
    ):
        walked = walked_track_circuits(geometry, stretches)
        where = "route" if key == "track_circuit" else "overlap"
        for tc in sorted(walked - set(listed)):
            out.append(Finding(st, name, tc, key, f"on the {where}'s path, not in the {where}"))
        for tc in sorted(set(listed) - walked):
            out.append(Finding(st, name, tc, key, f"in the {where}, not on its path"))
    sections = [tc for sec in route.release_sections for tc in sec]
    for tc in sorted(set(route.track_circuits) - set(sections)):
        out.append(Finding(st, name, tc, "release", "in the route, in no release section"))
    for tc in sorted(set(sections) - set(route.track_circuits)):
        out.append(Finding(st, name, tc, "release", "in a release section, not in the route"))
    for point, threats in flank_routes(station, route).items():
        for q in threats:
            if q not in route.conflicts:
                out.append(Finding(st, name, point, "flank",
                                   f"route {q} runs onto point {point} from the leg this route "
                                   f"does not take, and is not in conflict"))  # fmt: skip
    return out


def _elements(route: Route) -> dict[str, str | None]:
    """Element -> the position a route sets it in (None: a track circuit)."""
    out: dict[str, str | None] = dict.fromkeys(route.all_track_circuits)
    out.update({s.point: s.position for s in route.all_points})
    return out


def _opposing(station: Station, a: Route, b: Route) -> bool:
    """Opposite directions over a shared stretch of one track (head-on within the station)."""
    if a.direction == b.direction:
        return False
    try:
        wa, wb = _walk(station, a), _walk(station, b)
    except GeometryError:
        return False
    for lo, hi, t in wa.route + wa.overlap:
        for lo2, hi2, t2 in wb.route + wb.overlap:
            if t == t2 and lo < hi2 and lo2 < hi:
                return True
    return False


def check_conflicts(station: Station) -> list[Finding]:
    """Every two routes sharing a track circuit or a point (set differently, or either way unless
    one runs on through the other's overlap), starting at one signal, or opposing, conflict."""
    out: list[Finding] = []
    routes = station.routes
    for i, a in enumerate(routes):
        ea = _elements(a)
        for b in routes[i + 1 :]:
            eb = _elements(b)
            why = []
            differ = sorted(
                e for e in ea.keys() & eb.keys() if ea[e] is not None and ea[e] != eb[e]
            )
            shared = sorted(ea.keys() & eb.keys())
            if differ:
                why.append(("point " + differ[0], f"sets point {differ[0]} {ea[differ[0]]}, "
                            f"route {b.name} sets it {eb[differ[0]]}"))  # fmt: skip
            elif shared and not (onward(a, b) or onward(b, a)):
                why.append((shared[0], f"shares {', '.join(shared)} with route {b.name}"))
            if a.entry == b.entry:
                why.append(
                    (f"signal {a.entry}", f"starts at signal {a.entry} as route {b.name} does")
                )
            if _opposing(station, a, b):
                why.append((f"route {b.name}", f"runs against route {b.name}"))
            if not why:
                continue
            element, text = why[0]
            for r, other in ((a, b), (b, a)):
                if other.name not in r.conflicts:
                    t = text if r is a else text.replace(f"route {b.name}", f"route {a.name}")
                    out.append(Finding(station.number, r.name, element, "conflict",
                                       f"{t}; not listed as conflicting with {other.name}"))  # fmt: skip
    return out


def check_line(line: Line) -> list[Finding]:
    """Every station's routes against the geometry, then every pair of its routes."""
    geometry = LineGeometry(line)
    out: list[Finding] = []
    for number in sorted(line.stations):
        station = line.stations[number]
        for route in station.routes:
            out.extend(check_route(line, geometry, station, route))
        out.extend(check_conflicts(station))
    return out
