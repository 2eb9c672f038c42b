"""The shape of a scenario file, declared once (msgspec Structs, `schema.Shape`): its keys, their
defaults and bounds. `model.load_scenario` converts a file with `schema.convert` and
`schema.finite`, then checks what hangs on other keys (stretches that end after they start, the
trains an assertion names) and converts km/h to SI."""

from __future__ import annotations

import math
from typing import Annotated, Any

import msgspec
from msgspec import Meta

from ktcs_bench.schema import Shape

MAX_DURATION_S = 24 * 3600.0
"""The longest scenario (virtual time); the shipped ones run 200..900 s."""
MAX_LENGTH_M = 1_000_000.0
"""The longest line (1000 km): its tags and resources are laid out one by one."""

Text = str | int
"""A name; a number is taken as its digits."""
AtLeast0 = Annotated[float, Meta(ge=0.0)]
AtLeast01 = Annotated[float, Meta(ge=0.1)]
AtLeast1 = Annotated[float, Meta(ge=1.0)]

INFINITE = frozenset({"active_until_s"})
"""The one number that may be infinite: a protection zone active until the end."""


class TagsShape(Shape):
    at_m: tuple[float, ...] | None = None  # the tags one by one; else every spacing_m
    spacing_m: AtLeast1 | None = None
    first_m: float = 0.0
    extra_m: tuple[float, ...] = ()


class GradientShape(Shape):
    from_m: float
    permille: float


class SpeedLimitShape(Shape):
    from_m: float
    to_m: float
    speed_kmh: AtLeast0


class ZoneShape(Shape):
    from_m: float
    to_m: float
    active_from_s: float = 0.0
    active_until_s: float = math.inf


class StationShape(Shape):
    name: Text
    stop_mark_m: float
    dwell_s: AtLeast0 = 20.0


class TrackCircuitShape(Shape):
    from_m: float
    to_m: float
    code_kmh: AtLeast0
    id: Text | None = None  # default: TC<n>, n its place in the list from 1
    target_distance_m: float | None = None


class LineShape(Shape):
    length_m: Annotated[float, Meta(ge=1.0, le=MAX_LENGTH_M)]
    tags: TagsShape | None = None
    gradients: tuple[GradientShape, ...] = ()
    speed_limits: tuple[SpeedLimitShape, ...] = ()
    protection_zones: tuple[ZoneShape, ...] = ()
    stations: tuple[StationShape, ...] = ()
    track_circuits: tuple[TrackCircuitShape, ...] = ()


class ResistanceShape(Shape):
    a: float = 0.005
    b: float = 0.0001
    c: float = 0.00002


class TrainShape(Shape):
    id: Text
    start_m: float
    length_m: AtLeast1 = 200.0
    max_speed_kmh: AtLeast1 = 80.0
    accel_kmhps: AtLeast01 = 3.0
    service_brake_kmhps: AtLeast01 = 3.0
    emergency_brake_kmhps: AtLeast01 = 4.0
    brake_build_up_s: AtLeast0 = 1.0
    driver_speed_kmh: AtLeast0 = 80.0
    mode: Text = "atcs"
    ato: bool = False
    recovery: bool = False
    safety_distance_m: AtLeast0 = 50.0
    service_brake: Text = "enabled"
    inattentive_until_eb: bool = False
    eb_release_delay_s: float | None = 5.0  # null: the emergency brake is never released
    tacho_error: AtLeast0 = 0.01
    missed_tags: tuple[AtLeast0, ...] = ()
    depart_at_s: AtLeast0 = 0.0
    resistance: ResistanceShape = msgspec.field(default_factory=ResistanceShape)


class PointShape(Shape):
    at_m: float
    id: Text
    required: Text = "reverse"


class ResourceManagerShape(Shape):
    resource_length_m: Annotated[float, Meta(ge=10.0)]
    points: tuple[PointShape, ...] = ()


class ScenarioShape(Shape):
    line: LineShape
    trains: tuple[TrainShape, ...]
    duration_s: Annotated[float, Meta(ge=0.1, le=MAX_DURATION_S)]
    dt_s: Annotated[float, Meta(ge=0.001)] = 0.1
    name: Text | None = None  # default: the file's name
    description: Text = ""
    resource_manager: ResourceManagerShape | None = None
    assertions: tuple[
        dict[Any, Any], ...
    ] = ()  # one kind each, its arguments free: checked in code
    stop_when_all_stopped: bool = False
