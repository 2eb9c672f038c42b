"""Station and line data as frozen dataclasses: what the IXL, trackside, ATC and charts run on.

Positions are metres of chainage along the line; "up" is the direction of rising chainage (station
18 towards 22), "down" the other. A station owns its track circuits, points, signals and routes; the
line owns the plain-line track circuits (each owned by one station, whose IXL and ATC handle it),
the intervals between stations, gradients, speed limits and the ATC speed-code table. Nothing here
reads files: `loader.py` builds these objects and checks them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

Direction = Literal["up", "down"]
PointPosition = Literal["normal", "reverse"]

DIRECTIONS: tuple[Direction, ...] = ("up", "down")
POINT_POSITIONS: tuple[PointPosition, ...] = ("normal", "reverse")
SIGNAL_KINDS = ("home", "starting", "shunt", "marker")
# Aspects from most restrictive to least: stop, shunt proceed (white), caution, reduce, proceed.
ASPECT_ORDER: tuple[str, ...] = ("R", "W", "Y", "YG", "G")


def more_restrictive(a: str, b: str) -> str:
    """The more restrictive of two aspects."""
    return a if ASPECT_ORDER.index(a) <= ASPECT_ORDER.index(b) else b


def opposite(direction: Direction) -> Direction:
    return "down" if direction == "up" else "up"


@dataclass(frozen=True, slots=True)
class TrackCircuit:
    name: str
    from_m: float
    to_m: float
    length_m: float
    station: int
    tracks: tuple[str, ...] = ()  # station tracks it carries; empty = every track (plain line)

    def on_track(self, track: str) -> bool:
        return not self.tracks or track in self.tracks

    def covers(self, position_m: float) -> bool:
        return self.from_m <= position_m <= self.to_m


@dataclass(frozen=True, slots=True)
class Point:
    """A point (turnout) and its geometry (SPEC §6.7): a train running `facing` meets its toe and
    leaves by the leg the blades lie in; from a leg it runs out over the toe (trailing). `toe`,
    `normal` and `reverse` name the station track on each side; None at the toe is the plain
    line. The toe is on the low-chainage side of a point facing up, the high side facing down."""

    name: str
    track_circuits: tuple[str, ...]
    position_m: float
    facing: Direction
    normal: str
    reverse: str
    toe: str | None = None
    throw_time_s: float = 4.0

    def leg(self, position: PointPosition) -> str:
        """The track the leg of `position` leads to."""
        return self.normal if position == "normal" else self.reverse

    def side(self, upward: bool) -> Literal["toe", "legs"]:
        """The side a train running up (`upward`) or down comes to the point from."""
        return "toe" if (self.facing == "up") == upward else "legs"


@dataclass(frozen=True, slots=True)
class Signal:
    name: str
    kind: str  # home | starting | shunt | marker (a route exit with no lamps: block limit, buffer)
    direction: Direction
    position_m: float
    aspects: tuple[str, ...] = ()
    track: str | None = None

    @property
    def has_lamps(self) -> bool:
        return self.kind != "marker"


@dataclass(frozen=True, slots=True)
class PointSetting:
    point: str
    position: PointPosition


@dataclass(frozen=True, slots=True)
class Route:
    name: str
    entry: str
    exit: str
    direction: Direction
    points: tuple[PointSetting, ...]
    track_circuits: tuple[str, ...]
    overlap_track_circuits: tuple[str, ...]
    overlap_points: tuple[PointSetting, ...]
    conflicts: tuple[str, ...]
    approach: tuple[str, ...]
    release_sections: tuple[tuple[str, ...], ...]
    aspect: str
    approach_release_s: float = 90.0
    overlap_release_s: float = 30.0
    speed_limit_kmh: float | None = None

    @property
    def all_track_circuits(self) -> tuple[str, ...]:
        return self.track_circuits + self.overlap_track_circuits

    @property
    def all_points(self) -> tuple[PointSetting, ...]:
        return self.points + self.overlap_points


@dataclass(frozen=True)
class Station:
    number: int
    name: str
    file: str
    tracks: tuple[str, ...]
    track_circuits: tuple[TrackCircuit, ...]
    points: tuple[Point, ...]
    signals: tuple[Signal, ...]
    routes: tuple[Route, ...]
    _tc: dict[str, TrackCircuit] = field(default_factory=dict, repr=False, compare=False)
    _pt: dict[str, Point] = field(default_factory=dict, repr=False, compare=False)
    _sg: dict[str, Signal] = field(default_factory=dict, repr=False, compare=False)
    _rt: dict[str, Route] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._tc.update({t.name: t for t in self.track_circuits})
        self._pt.update({p.name: p for p in self.points})
        self._sg.update({s.name: s for s in self.signals})
        self._rt.update({r.name: r for r in self.routes})

    def track_circuit(self, name: str) -> TrackCircuit:
        return self._tc[name]

    def point(self, name: str) -> Point:
        return self._pt[name]

    def signal(self, name: str) -> Signal:
        return self._sg[name]

    def route(self, name: str) -> Route:
        return self._rt[name]

    def has_route(self, name: str) -> bool:
        return name in self._rt

    @property
    def lamp_signals(self) -> tuple[Signal, ...]:
        return tuple(s for s in self.signals if s.has_lamps)


@dataclass(frozen=True, slots=True)
class Interval:
    """The plain line between two stations (or from a station to the edge of the lab: boundary)."""

    name: str  # "1820": west station then east station
    west: int
    east: int
    from_m: float
    to_m: float
    track_circuits: tuple[str, ...]  # in up (rising chainage) order
    default_direction: Direction = "up"
    boundary: bool = False

    def toward(self, station: int) -> Direction:
        """The direction of a train running in this interval towards `station`."""
        return "down" if station == self.west else "up"


@dataclass(frozen=True, slots=True)
class Gradient:
    from_m: float
    to_m: float
    permille: float  # positive = rising in the up direction


@dataclass(frozen=True, slots=True)
class SpeedLimit:
    from_m: float
    to_m: float
    kmh: float


@dataclass(frozen=True, slots=True)
class SpeedCode:
    code: int
    kmh: float


@dataclass(frozen=True)
class Line:
    name: str
    file: str
    start_m: float
    end_m: float
    stations: dict[int, Station]
    track_circuits: tuple[TrackCircuit, ...]  # plain line only
    intervals: tuple[Interval, ...]
    gradients: tuple[Gradient, ...]
    speed_limits: tuple[SpeedLimit, ...]
    speed_codes: tuple[SpeedCode, ...]  # sorted by speed, lowest (most restrictive) first
    service_brake_mps2: float = 0.5  # the code steps' braking rate on the level
    brake_build_up_s: float = 1.0  # the code steps' run-on before that braking (atc.*)
    tag_spacing_m: float = 100.0
    # each station's view, made once (`view`: what it works out, it keeps)
    _views: dict[int, StationView] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def station(self, number: int) -> Station:
        return self.stations[number]

    def all_track_circuits(self) -> tuple[TrackCircuit, ...]:
        tcs = list(self.track_circuits)
        for st in self.stations.values():
            tcs.extend(st.track_circuits)
        return tuple(sorted(tcs, key=lambda t: (t.from_m, t.name)))

    def view(self, number: int) -> StationView:
        view = self._views.get(number)
        if view is None:
            view = self._views[number] = StationView(self, self.stations[number])
        return view

    def gradient_between(self, a_m: float, b_m: float) -> float:
        """The lowest gradient (‰, up sense) over [a, b]; 0 where the table is silent."""
        lo, hi = min(a_m, b_m), max(a_m, b_m)
        values = [g.permille for g in self.gradients if g.from_m < hi and g.to_m > lo]
        return min(values) if values else 0.0

    def highest_gradient_between(self, a_m: float, b_m: float) -> float:
        lo, hi = min(a_m, b_m), max(a_m, b_m)
        values = [g.permille for g in self.gradients if g.from_m < hi and g.to_m > lo]
        return max(values) if values else 0.0

    def speed_limit_between(self, a_m: float, b_m: float) -> float:
        lo, hi = min(a_m, b_m), max(a_m, b_m)
        values = [s.kmh for s in self.speed_limits if s.from_m < hi and s.to_m > lo]
        return min(values) if values else max(c.kmh for c in self.speed_codes)

    @property
    def most_restrictive_code(self) -> SpeedCode:
        return self.speed_codes[0]


@dataclass(frozen=True)
class StationView:
    """One station as its IXL, trackside and ATC see it: its own data plus its part of the line."""

    line: Line
    station: Station

    @property
    def number(self) -> int:
        return self.station.number

    # worked out once a view (the line is frozen): an ATC asks its intervals for every code
    @cached_property
    def plain_track_circuits(self) -> tuple[TrackCircuit, ...]:
        return tuple(t for t in self.line.track_circuits if t.station == self.number)

    @cached_property
    def track_circuits(self) -> tuple[TrackCircuit, ...]:
        """Every track circuit this station's IXL and ATC handle, in chainage order."""
        tcs = self.station.track_circuits + self.plain_track_circuits
        return tuple(sorted(tcs, key=lambda t: (t.from_m, t.name)))

    @cached_property
    def intervals(self) -> tuple[Interval, ...]:
        """Adjacent intervals, west first."""
        west = [i for i in self.line.intervals if i.east == self.number]
        east = [i for i in self.line.intervals if i.west == self.number]
        return tuple(west + east)

    def interval_of_exit(self, route: Route) -> Interval | None:
        """The interval a route leads into (its exit is a block-limit marker), else None."""
        exit_signal = self.station.signal(route.exit)
        if exit_signal.kind != "marker":
            return None
        for iv in self.intervals:
            if route.direction == "up" and iv.west == self.number:
                return iv
            if route.direction == "down" and iv.east == self.number:
                return iv
        return None

    def owned_half(self, interval: Interval) -> tuple[str, ...]:
        """The track circuits of `interval` that this station owns, in up order."""
        mine = {t.name for t in self.plain_track_circuits}
        return tuple(t for t in interval.track_circuits if t in mine)
