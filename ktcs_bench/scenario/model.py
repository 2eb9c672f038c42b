"""Reading a scenario file into checked objects; every mistake is one ConfigError (file, key, why).

The file's shape -- the line (tags, gradients, speed limits, protection zones, stations, kTCS
track-circuit codes), the trains, an optional resource manager and the assertions -- is declared
in `shapes.py` and converted by `schema.convert` (no number NaN or infinite: `schema.finite`);
what hangs on other keys is checked here, and km/h and km/h/s are converted to SI, at the edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.datafiles import YamlReader, load_mapping
from ktcs_bench.errors import UsageError, excerpt, say_seconds
from ktcs_bench.scenario.shapes import (
    INFINITE,
    LineShape,
    ResourceManagerShape,
    ScenarioShape,
    TagsShape,
    TrainShape,
)
from ktcs_bench.schema import READER, convert, finite
from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import LineData, Station, TrainConfig
from ktcs_bench.train.mrsp import Restriction
from ktcs_bench.train.resources import Resource
from ktcs_bench.train.units import kmh

MAX_CYCLES = 500_000
"""The most cycles (duration_s / dt_s) a scenario runs: every cycle of every train is kept for
the report (some kB a cycle), so more cannot fit (a 24 h scenario takes dt_s 0.2 or more)."""

ASSERTION_KINDS = (
    "min_gap",
    "stops_at",
    "never_passes",
    "never_exceeds_ebd",
    "event",
    "reaches",
    "max_speed",
)


@dataclass(frozen=True)
class TrackCircuit:
    id: str
    start: float
    end: float
    speed: float
    target_distance: float | None
    """Distance from this circuit's entry to the stop point, m (None: no stop point)."""


@dataclass(frozen=True)
class Zone:
    start: float
    end: float
    active_from: float = 0.0
    active_until: float = math.inf


@dataclass(frozen=True)
class Assertion:
    kind: str
    args: dict[str, Any]
    place: str


@dataclass
class Scenario:
    path: Path
    name: str
    description: str
    duration: float
    dt: float
    line: LineData
    trains: list[TrainConfig]
    zones: list[Zone] = field(default_factory=list)
    track_circuits: list[TrackCircuit] = field(default_factory=list)
    resources: list[Resource] | None = None
    point_throw_time: float = 4.0
    stop_when_all_stopped: bool = False
    assertions: list[Assertion] = field(default_factory=list)


def load_scenario(path: str | Path) -> Scenario:
    p = Path(path)
    r = YamlReader(p)
    doc = convert(load_mapping(p, "scenario"), ScenarioShape, p, style=READER)
    finite(doc, p, infinite=INFINITE, style=READER)
    lm = doc.line
    length = lm.length_m
    for i, s in enumerate(lm.speed_limits):
        if s.to_m <= s.from_m:
            raise r.fail(f"line.speed_limits[{i}].to_m", f"must lie after from_m ({s.from_m})")
    try:
        grads = sorted((g.from_m, g.permille) for g in lm.gradients)
        gradient = GradientProfile(tuple(g[0] for g in grads), tuple(g[1] for g in grads))
    except UsageError as exc:
        raise r.fail("line.gradients", str(exc)) from None
    line = LineData(
        length,
        _tags(r, lm.tags, length),
        gradient,
        [Restriction(s.from_m, s.to_m, kmh(s.speed_kmh)) for s in lm.speed_limits],
        sorted(
            (Station(str(s.name), s.stop_mark_m, s.dwell_s) for s in lm.stations),
            key=lambda s: s.stop_mark,
        ),
    )
    trains = [_train(r, t, f"trains[{i}]") for i, t in enumerate(doc.trains)]
    if not trains:
        raise r.fail("trains", "at least one train is needed")
    ids = [t.train_id for t in trains]
    if len(set(ids)) != len(ids):
        raise r.fail("trains", "train ids must be unique")
    resources = None
    if doc.resource_manager is not None:
        resources = _resources(doc.resource_manager, length)
    duration, dt = doc.duration_s, doc.dt_s
    if duration / dt > MAX_CYCLES:
        raise r.fail(
            "dt_s",
            f"{say_seconds(duration)} in steps of {dt:g} s is {duration / dt:.0f} cycles; a "
            f"scenario runs at most {MAX_CYCLES} (a longer dt_s, or a shorter duration_s)",
        )
    return Scenario(
        path=p,
        name=str(doc.name) if doc.name is not None else p.stem,
        description=str(doc.description),
        duration=duration,
        dt=dt,
        line=line,
        trains=trains,
        zones=[
            Zone(z.from_m, z.to_m, z.active_from_s, z.active_until_s) for z in lm.protection_zones
        ],
        track_circuits=sorted(_track_circuits(lm), key=lambda t: t.start),
        resources=resources,
        stop_when_all_stopped=doc.stop_when_all_stopped,
        assertions=_assertions(r, doc.assertions, ids),
    )


def _tags(r: YamlReader, tm: TagsShape | None, length: float) -> list[float]:
    """Where the balise tags lie: listed (`at_m`) or every `spacing_m` from `first_m`, with any
    `extra_m` besides."""
    if tm is None:
        return []
    if tm.at_m is not None:
        tags = list(tm.at_m)
    elif tm.spacing_m is None:
        raise r.fail("line.tags.spacing_m", "missing")
    else:
        n = int(math.floor((length - tm.first_m) / tm.spacing_m + 1e-9)) + 1
        tags = [tm.first_m + i * tm.spacing_m for i in range(n)]
    return sorted(set(tags) | set(tm.extra_m))


def _track_circuits(lm: LineShape) -> list[TrackCircuit]:
    return [
        TrackCircuit(
            f"TC{i + 1}" if t.id is None else str(t.id),
            t.from_m,
            t.to_m,
            kmh(t.code_kmh),
            t.target_distance_m,
        )
        for i, t in enumerate(lm.track_circuits)
    ]


def _resources(rm: ResourceManagerShape, length: float) -> list[Resource]:
    """The resource manager's resources: the line cut every `resource_length_m`, each holding
    the point (and the position it needs) that lies in it."""
    points = {pt.at_m: (str(pt.id), str(pt.required)) for pt in rm.points}
    resources = []
    x, k = 0.0, 1
    while x < length:
        end = min(x + rm.resource_length_m, length)
        pt_here = [(at, v) for at, v in points.items() if x <= at < end]
        res = Resource(f"R{k}", x, end)
        if pt_here:
            res.point, res.required = pt_here[0][1]
        resources.append(res)
        x, k = end, k + 1
    return resources


def _assertions(
    r: YamlReader, items: tuple[dict[Any, Any], ...], ids: list[str]
) -> list[Assertion]:
    assertions = []
    for i, am in enumerate(items):
        place = f"assertions[{i}]"
        if len(am) != 1:
            raise r.fail(place, f"one assertion per item, one of {', '.join(ASSERTION_KINDS)}")
        kind, args = next(iter(am.items()))
        if kind not in ASSERTION_KINDS:
            raise r.fail(
                f"{place}.{kind}", f"unknown assertion (one of {', '.join(ASSERTION_KINDS)})"
            )
        args_m = r.mapping(args, f"{place}.{kind}")
        for key in (kinds.TRAIN, "follower", "leader"):
            if key in args_m and r.word(args_m[key], f"{place}.{kind}.{key}") not in ids:
                raise r.fail(
                    f"{place}.{kind}.{key}", f"no train {excerpt(args_m[key])} (trains: {ids})"
                )
        assertions.append(Assertion(kind, args_m, f"{place}.{kind}"))
    return assertions


def _train(r: YamlReader, m: TrainShape, place: str) -> TrainConfig:
    mode = str(m.mode)
    if mode not in ("atcs", "ktcs"):
        raise r.fail(f"{place}.mode", f"must be atcs or ktcs, got {excerpt(mode)}")
    sb = str(m.service_brake)
    if sb not in ("enabled", "disabled"):
        raise r.fail(f"{place}.service_brake", f"must be enabled or disabled, got {excerpt(sb)}")
    try:
        params = TrainParams(
            length=m.length_m,
            max_speed=kmh(m.max_speed_kmh),
            max_traction=kmh(m.accel_kmhps),
            service_decel=kmh(m.service_brake_kmhps),
            emergency_decel=kmh(m.emergency_brake_kmhps),
            brake_build_up=m.brake_build_up_s,
            resistance_a=m.resistance.a,
            resistance_b=m.resistance.b,
            resistance_c=m.resistance.c,
        )
    except UsageError as exc:
        raise r.fail(place, str(exc)) from None
    return TrainConfig(
        train_id=str(m.id),
        params=params,
        start=m.start_m,
        mode=mode,
        driver_speed=kmh(m.driver_speed_kmh),
        ato=m.ato,
        recovery=m.recovery,
        safety_distance=m.safety_distance_m,
        service_brake_enabled=sb == "enabled",
        inattentive_until_eb=m.inattentive_until_eb,
        eb_release_delay=m.eb_release_delay_s,
        tacho_error=m.tacho_error,
        missed_tags=frozenset(int(x) for x in m.missed_tags),
        depart_at=m.depart_at_s,
    )
