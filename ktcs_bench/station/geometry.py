"""Where a station's tracks run, from its points' geometry (SPEC §6.7).

A train is on one *track* at a time: a station track by name, or the plain line (None). Tracks run
side by side in chainage, so where a train is along the line is its chainage and its track; the
track changes only at a point: a train meets a point from its toe side (facing) or from one of its
legs (trailing), and only if it is on the track that side names (`meets`). Each station track runs
between the points that lead to it (`track_extent`); where no point bounds it (a siding), as far
as its track circuits go.

Used by the track-circuit model (which moves trains by the blades) and by the checks of station
data: the loader (`walk_route`: each route runs over its points in the positions it requires, from
its entry signal's track to its exit's) and `chart check` (the track circuits of that walk are the
route's own).
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

from ktcs_bench.station.model import Line, Point, PointPosition, Route, Station, TrackCircuit

Track = str | None
"""A station track by name, or None: the plain line."""

Meeting = Literal["toe", "normal", "reverse"]


def meets(point: Point, track: Track, upward: bool) -> Meeting | None:
    """How a train on `track` running up (`upward`) or down comes to `point`: at its toe, at the
    end of its normal or reverse leg, or not at all (the point is on another track)."""
    if point.side(upward) == "toe":
        return "toe" if track == point.toe else None
    if track == point.normal:
        return "normal"
    if track == point.reverse:
        return "reverse"
    return None


def beyond(point: Point, meeting: Meeting, position: PointPosition) -> Track:
    """The track a train is on once past `point`: met at the toe, the leg the blades lie in
    (`position`); met at a leg, the toe's."""
    return point.leg(position) if meeting == "toe" else point.toe


def _high_side(point: Point) -> tuple[Track, ...]:
    """The tracks on the point's high-chainage side."""
    return (point.normal, point.reverse) if point.facing == "up" else (point.toe,)


def _low_side(point: Point) -> tuple[Track, ...]:
    return (point.toe,) if point.facing == "up" else (point.normal, point.reverse)


def track_extent(station: Station, track: str) -> tuple[float, float] | None:
    """From where to where (m) the station track runs: between the points that lead to it, or
    to the end of its track circuits where no point closes it (a siding); None: nowhere."""
    starts = [p.position_m for p in station.points if track in _high_side(p)]
    ends = [p.position_m for p in station.points if track in _low_side(p)]
    tcs = [t for t in station.track_circuits if track in t.tracks]
    lo = min(starts) if starts else min((t.from_m for t in tcs), default=None)
    hi = max(ends) if ends else max((t.to_m for t in tcs), default=None)
    if lo is None or hi is None or hi < lo:
        return None
    return lo, hi


class LineGeometry:
    """The points of a whole line in chainage order, and where each station track runs."""

    def __init__(self, line: Line) -> None:
        self.line = line
        found = [(p.position_m, st.number, p) for st in line.stations.values() for p in st.points]
        found.sort(key=lambda x: (x[0], x[1], x[2].name))
        self.points: tuple[tuple[float, int, Point], ...] = tuple(found)
        self._at = [x[0] for x in found]
        self.extents: dict[tuple[int, str], tuple[float, float]] = {}
        for st in line.stations.values():
            for t in st.tracks:
                ext = track_extent(st, t)
                if ext is not None:
                    self.extents[(st.number, t)] = ext
        self._line_tcs = {t.name for t in line.track_circuits}
        # track circuits over a point's plain-line toe: they carry the plain line there too
        self._plain_toe = {
            tc for st in line.stations.values() for p in st.points if p.toe is None
            for tc in p.track_circuits
        }  # fmt: skip

    def point(self, station: int, name: str) -> Point:
        return self.line.station(station).point(name)

    def passed(self, start: float, end: float) -> Iterator[tuple[int, Point]]:
        """The points a train's end running from `start` to `end` goes over, in its order: those
        beyond `start` up to and at `end` (an end at a point has gone over it)."""
        if end > start:
            i, j = bisect.bisect_right(self._at, start), bisect.bisect_right(self._at, end)
            for _, st, p in self.points[i:j]:
                yield st, p
        elif end < start:
            i, j = bisect.bisect_left(self._at, end), bisect.bisect_left(self._at, start)
            for _, st, p in reversed(self.points[i:j]):
                yield st, p

    def runs(self, track: str, at_m: float) -> bool:
        """Station track `track` runs at `at_m` (at some station of the line)."""
        return any(lo <= at_m <= hi for (_, t), (lo, hi) in self.extents.items() if t == track)

    def track_at(self, at_m: float, track: Track) -> Track:
        """The track a train put at `at_m` and said to be on `track` is on: that station track
        where it runs there, else the plain line; ValueError inside a station's points where the
        track does not run (there is no plain line there)."""
        if track is not None and self.runs(track, at_m):
            return track
        for st in self.line.stations.values():
            inner = [p.position_m for p in st.points]
            if inner and min(inner) < at_m < max(inner):
                have = sorted(t for (n, t), (lo, hi) in self.extents.items()
                              if n == st.number and lo <= at_m <= hi)  # fmt: skip
                raise ValueError(
                    f"no track {track!r} at {at_m:g} m in station {st.number} "
                    f"(tracks there: {', '.join(have) or 'none'})"
                )
        return None

    def carries(self, tc: TrackCircuit, track: Track) -> bool:
        """A train on `track` over the track circuit's stretch shunts it. A plain-line circuit
        (of the line file) carries the plain line only: a siding may run beside it."""
        if tc.name in self._line_tcs:
            return track is None
        if not tc.tracks or track in tc.tracks:
            return True
        return track is None and tc.name in self._plain_toe


# -- routes over the geometry ---------------------------------------------------------------------


class GeometryError(ValueError):
    """Station data whose point geometry and routes disagree: `place` is the key path."""

    def __init__(self, place: str, problem: str) -> None:
        super().__init__(f"{place}: {problem}")
        self.place, self.problem = place, problem


@dataclass(frozen=True, slots=True)
class RouteWalk:
    """A route run over the geometry: the stretches (from_m, to_m, track) of the route proper
    and of its overlap, in chainage order."""

    route: tuple[tuple[float, float, Track], ...]
    overlap: tuple[tuple[float, float, Track], ...]


def walk_route(station: Station, route: Route, place: str) -> RouteWalk:
    """Run `route` from its entry signal to its exit and on over its overlap, taking at each point
    it meets the leg the route sets (facing) or checking it trails in the position it sets.
    GeometryError where a leg leads elsewhere than the route's exit track, a point the route sets
    is never met, or a point met is not set."""
    entry, exit_ = station.signal(route.entry), station.signal(route.exit)
    upward = route.direction == "up"
    track: Track = entry.track
    ov_tcs = [station.track_circuit(t) for t in route.overlap_track_circuits]
    if ov_tcs:
        ov_end = max(t.to_m for t in ov_tcs) if upward else min(t.from_m for t in ov_tcs)
    else:
        ov_end = exit_.position_m
    settings = {s.point: (s.position, "points") for s in route.points}
    settings.update({s.point: (s.position, "overlap.points") for s in route.overlap_points})
    met: set[str] = set()
    stretches: list[tuple[float, float, Track]] = []
    at = entry.position_m
    ordered = sorted(station.points, key=lambda p: p.position_m, reverse=not upward)

    def run(to: float, track: Track) -> Track:
        nonlocal at
        for p in ordered:
            ahead = at < p.position_m <= to if upward else to <= p.position_m < at
            meeting = meets(p, track, upward) if ahead else None
            if meeting is None:
                continue
            if p.name not in settings:
                raise GeometryError(
                    f"{place}.points",
                    f"runs over point {p.name} (from its {meeting}) and does not set it",
                )
            position, key = settings[p.name]
            if meeting != "toe" and meeting != position:
                raise GeometryError(
                    f"{place}.{key}",
                    f"runs over point {p.name} trailing from its {meeting} leg (track "
                    f"{track}) but sets it {position}",
                )
            met.add(p.name)
            stretches.append((min(at, p.position_m), max(at, p.position_m), track))
            at = p.position_m
            track = beyond(p, meeting, position)
        if to != at:
            stretches.append((min(at, to), max(at, to), track))
        at = to
        return track

    exit_track = run(exit_.position_m, track)
    if exit_.track is not None and exit_track != exit_.track:
        raise GeometryError(
            f"{place}.exit",
            f"the points as the route sets them lead to track {exit_track or 'plain line'}, "
            f"not signal {exit_.name}'s track {exit_.track}",
        )
    proper = len(stretches)
    run(ov_end, exit_track)
    for name, (_, key) in settings.items():
        if name not in met:
            raise GeometryError(f"{place}.{key}", f"sets point {name} it never runs over")
    return RouteWalk(tuple(sorted(stretches[:proper])), tuple(sorted(stretches[proper:])))


def walked_track_circuits(
    geometry: LineGeometry, stretches: tuple[tuple[float, float, Track], ...]
) -> set[str]:
    """The track circuits a train on the stretches shunts (each of its tracks)."""
    out: set[str] = set()
    for lo, hi, track in stretches:
        for tc in geometry.line.all_track_circuits():
            if tc.from_m < hi and tc.to_m > lo and geometry.carries(tc, track):
                out.add(tc.name)
    return out
