"""The shapes of the station and line files, declared once (msgspec Structs, `schema.Shape`):
which keys there are, which are optional and their defaults, and each value's type. What hangs on
other parts -- references, geometry, defaults computed from other keys -- `loader` checks after
`schema.convert`.
"""

from __future__ import annotations

from typing import Any

import msgspec

from ktcs_bench.schema import Shape

Text = str | int
"""A name or a word of the file; a number is taken as its digits (`tracks: [1, 2]`)."""


# -- station files -----------------------------------------------------------------------------


class TrackCircuitShape(Shape):
    name: Text
    from_m: float
    to_m: float
    length_m: float | None = None  # default: to_m - from_m
    tracks: tuple[Text, ...] | None = None


class PointShape(Shape):
    name: Text
    track_circuits: tuple[Text, ...]
    position_m: float
    facing: Text  # up | down: the direction of a train that meets the toe
    normal: Text  # the station track the normal leg leads to
    reverse: Text  # ... and the reverse leg
    toe: Text | None = None  # the station track at the toe; none: the plain line
    throw_time_s: float = 4.0


class SignalShape(Shape):
    name: Text
    kind: Text
    direction: Text
    position_m: float
    aspects: tuple[Text, ...] | None = None
    track: Text | None = None


class SettingShape(Shape):
    point: Text
    position: Text


class OverlapShape(Shape):
    track_circuits: tuple[Text, ...]
    points: tuple[SettingShape, ...] | None = None


class RouteShape(Shape):
    name: Text
    entry: Text
    exit: Text
    track_circuits: tuple[Text, ...]
    approach: tuple[Text, ...]
    points: tuple[SettingShape, ...] | None = None
    overlap: OverlapShape | None = None
    conflicts: tuple[Text, ...] | None = None
    release_sections: tuple[object, ...] | None = None  # each a non-empty list: checked in code
    aspect: Text | None = None  # default: G, W for a shunt signal
    speed_limit_kmh: float | None = None
    approach_release_s: float = 90.0
    overlap_release_s: float = 30.0


class StationShape(Shape):
    station: int
    tracks: tuple[Text, ...]
    track_circuits: tuple[TrackCircuitShape, ...]
    points: tuple[PointShape, ...]
    signals: tuple[SignalShape, ...]
    routes: tuple[RouteShape, ...]
    name: Text | None = None  # default: "Station <number>"


# -- the line file -----------------------------------------------------------------------------


class StationRefShape(Shape):
    number: int
    file: Text


class LineTrackCircuitShape(Shape):
    name: Text
    from_m: float
    to_m: float
    station: int
    length_m: float | None = None  # default: to_m - from_m


class IntervalShape(Shape):
    name: Text
    west: int
    east: int
    track_circuits: tuple[Text, ...]
    from_m: float
    to_m: float
    boundary: bool = False
    default_direction: Text = "up"


class GradientShape(Shape):
    from_m: float
    to_m: float
    permille: float


class SpeedLimitShape(Shape):
    from_m: float
    to_m: float
    kmh: float


class SpeedCodeShape(Shape):
    code: int
    kmh: float


class AtcShape(Shape):
    codes: tuple[SpeedCodeShape, ...]
    service_brake_mps2: float = 0.5
    """The service deceleration on the level the code steps are graded with, m/s² (corrected
    for the gradient ahead)."""
    brake_build_up_s: float = 1.0
    """How long a train runs on at its speed before that braking takes hold, s: the code steps
    leave the distance it runs meanwhile."""


class TagsShape(Shape):
    spacing_m: float = 100.0


class LineShape(Shape):
    line: Text
    start_m: float
    end_m: float
    stations: tuple[StationRefShape, ...]
    track_circuits: tuple[LineTrackCircuitShape, ...]
    intervals: tuple[IntervalShape, ...]
    gradients: tuple[GradientShape, ...]
    speed_limits: tuple[SpeedLimitShape, ...]
    atc: AtcShape
    tags: TagsShape = msgspec.field(default_factory=TagsShape)


# -- timetable files ---------------------------------------------------------------------------


class TrainDataShape(Shape):
    length_m: float
    max_speed_kmh: float
    traction_kmh_per_s: float
    service_brake_kmh_per_s: float
    emergency_brake_kmh_per_s: float


class StopShape(Shape):
    station: int
    track: Text
    stop_m: float
    dwell_s: float = 0.0


class EntersShape(Shape):
    track_circuit: Text
    at_s: float = 0.0


class TimetableTrainShape(Shape):
    id: Text
    train: Text
    direction: Text
    stops: tuple[StopShape, ...]
    enters: EntersShape | None = None
    leaves_lab: bool = False
    depart_s: float = 0.0


class TimetableShape(Shape):
    timetable: Text
    train_data: dict[Any, Any]  # name -> TrainDataShape, converted one by one (the path names it)
    trains: tuple[TimetableTrainShape, ...]
    line: Text | None = None
