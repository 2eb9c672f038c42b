"""Reading a scenario file into checked objects; every mistake is one ConfigError (file, key, why).

Owns the scenario YAML schema: the line (tags, gradients, speed limits, protection zones,
stations, kTCS track-circuit codes), the trains, an optional resource manager and the assertions.
km/h and km/h/s are converted to SI here, at the edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.datafiles import YamlReader, load_mapping
from ktcs_bench.errors import UsageError, excerpt, say_seconds
from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import LineData, Station, TrainConfig
from ktcs_bench.train.mrsp import Restriction
from ktcs_bench.train.resources import Resource
from ktcs_bench.train.units import kmh

MAX_DURATION_S = 24 * 3600.0
"""The longest scenario (virtual time); the shipped ones run 200..900 s."""
MAX_CYCLES = 500_000
"""The most cycles (duration_s / dt_s) a scenario runs: every cycle of every train is kept for
the report (some kB a cycle), so more cannot fit (a 24 h scenario takes dt_s 0.2 or more)."""
MAX_LENGTH_M = 1_000_000.0
"""The longest line (1000 km): its tags and resources are laid out one by one."""

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


_SCENARIO_KEYS = {
    "name",
    "description",
    "duration_s",
    "dt_s",
    "line",
    "trains",
    "resource_manager",
    "assertions",
    "stop_when_all_stopped",
}
_LINE_KEYS = {
    "length_m",
    "tags",
    "gradients",
    "speed_limits",
    "protection_zones",
    "stations",
    "track_circuits",
}


def load_scenario(path: str | Path) -> Scenario:
    p = Path(path)
    r = YamlReader(p)
    doc = load_mapping(p, "scenario")
    r.known(doc, _SCENARIO_KEYS, "")
    line_m = r.mapping(doc.get("line"), "line")
    r.known(line_m, _LINE_KEYS, "line")
    length = r.num(line_m, "length_m", "line", minimum=1.0, maximum=MAX_LENGTH_M)
    tags = _tags(r, line_m, length)
    gradient = _gradient(r, line_m)
    restrictions = _restrictions(r, line_m)
    zones = _zones(r, line_m)
    stations = _stations(r, line_m)
    tcs = _track_circuits(r, line_m)
    line = LineData(length, tags, gradient, restrictions, stations)
    trains = []
    for i, t in enumerate(r.seq(doc.get("trains"), "trains")):
        trains.append(_train(r, r.mapping(t, f"trains[{i}]"), f"trains[{i}]"))
    if not trains:
        raise r.fail("trains", "at least one train is needed")
    ids = [t.train_id for t in trains]
    if len(set(ids)) != len(ids):
        raise r.fail("trains", "train ids must be unique")
    resources = None
    if "resource_manager" in doc:
        resources = _resources(r, doc["resource_manager"], length)
    assertions = _assertions(r, doc, ids)
    duration = r.num(doc, "duration_s", "", minimum=0.1, maximum=MAX_DURATION_S)
    dt = r.num(doc, "dt_s", "", default=0.1, minimum=0.001)
    if duration / dt > MAX_CYCLES:
        raise r.fail(
            "dt_s",
            f"{say_seconds(duration)} in steps of {dt:g} s is {duration / dt:.0f} cycles; a "
            f"scenario runs at most {MAX_CYCLES} (a longer dt_s, or a shorter duration_s)",
        )
    return Scenario(
        path=p,
        name=r.text(doc, "name", "", default=p.stem),
        description=r.text(doc, "description", "", default=""),
        duration=duration,
        dt=dt,
        line=line,
        trains=trains,
        zones=zones,
        track_circuits=sorted(tcs, key=lambda t: t.start),
        resources=resources,
        stop_when_all_stopped=r.flag(doc, "stop_when_all_stopped", "", False),
        assertions=assertions,
    )


def _tags(r: YamlReader, line_m: dict[str, Any], length: float) -> list[float]:
    """Where the balise tags lie: listed (`at_m`) or every `spacing_m` from `first_m`, with any
    `extra_m` besides."""
    if "tags" not in line_m:
        return []
    tm = r.mapping(line_m["tags"], "line.tags")
    r.known(tm, {"spacing_m", "first_m", "at_m", "extra_m"}, "line.tags")
    if "at_m" in tm:
        tags = [
            r.value(x, f"line.tags.at_m[{i}]")
            for i, x in enumerate(r.seq(tm["at_m"], "line.tags.at_m"))
        ]
    else:
        spacing = r.num(tm, "spacing_m", "line.tags", minimum=1.0)
        first = r.num(tm, "first_m", "line.tags", default=0.0)
        n = int(math.floor((length - first) / spacing + 1e-9)) + 1
        tags = [first + i * spacing for i in range(n)]
    extra = [
        r.value(x, f"line.tags.extra_m[{i}]")
        for i, x in enumerate(r.seq(tm.get("extra_m", []), "line.tags.extra_m"))
    ]
    return sorted(set(tags) | set(extra))


def _gradient(r: YamlReader, line_m: dict[str, Any]) -> GradientProfile:
    grads: list[tuple[float, float]] = []
    for i, g in enumerate(r.seq(line_m.get("gradients", []), "line.gradients")):
        gm = r.mapping(g, f"line.gradients[{i}]")
        grads.append(
            (
                r.num(gm, "from_m", f"line.gradients[{i}]"),
                r.num(gm, "permille", f"line.gradients[{i}]"),
            )
        )
    grads.sort()
    try:
        return GradientProfile(tuple(g[0] for g in grads), tuple(g[1] for g in grads))
    except UsageError as exc:
        raise r.fail("line.gradients", str(exc)) from None


def _restrictions(r: YamlReader, line_m: dict[str, Any]) -> list[Restriction]:
    restrictions = []
    for i, s in enumerate(r.seq(line_m.get("speed_limits", []), "line.speed_limits")):
        place = f"line.speed_limits[{i}]"
        sm = r.mapping(s, place)
        start, end = r.num(sm, "from_m", place), r.num(sm, "to_m", place)
        if end <= start:
            raise r.fail(f"{place}.to_m", f"must lie after from_m ({start})")
        restrictions.append(Restriction(start, end, kmh(r.num(sm, "speed_kmh", place, minimum=0))))
    return restrictions


def _zones(r: YamlReader, line_m: dict[str, Any]) -> list[Zone]:
    zones = []
    for i, z in enumerate(r.seq(line_m.get("protection_zones", []), "line.protection_zones")):
        place = f"line.protection_zones[{i}]"
        zm = r.mapping(z, place)
        zones.append(
            Zone(
                r.num(zm, "from_m", place),
                r.num(zm, "to_m", place),
                r.num(zm, "active_from_s", place, default=0.0),
                r.num(zm, "active_until_s", place, default=math.inf, infinite=True),
            )
        )
    return zones


def _stations(r: YamlReader, line_m: dict[str, Any]) -> list[Station]:
    stations = []
    for i, s in enumerate(r.seq(line_m.get("stations", []), "line.stations")):
        place = f"line.stations[{i}]"
        sm = r.mapping(s, place)
        stations.append(
            Station(
                r.text(sm, "name", place),
                r.num(sm, "stop_mark_m", place),
                r.num(sm, "dwell_s", place, default=20.0, minimum=0.0),
            )
        )
    stations.sort(key=lambda s: s.stop_mark)
    return stations


def _track_circuits(r: YamlReader, line_m: dict[str, Any]) -> list[TrackCircuit]:
    tcs = []
    for i, t in enumerate(r.seq(line_m.get("track_circuits", []), "line.track_circuits")):
        place = f"line.track_circuits[{i}]"
        tm = r.mapping(t, place)
        td = tm.get("target_distance_m")
        tcs.append(
            TrackCircuit(
                r.text(tm, "id", place, default=f"TC{i + 1}"),
                r.num(tm, "from_m", place),
                r.num(tm, "to_m", place),
                kmh(r.num(tm, "code_kmh", place, minimum=0.0)),
                None if td is None else r.num(tm, "target_distance_m", place),
            )
        )
    return tcs


def _resources(r: YamlReader, section: object, length: float) -> list[Resource]:
    """The resource manager's resources: the line cut every `resource_length_m`, each holding
    the point (and the position it needs) that lies in it."""
    rm = r.mapping(section, "resource_manager")
    size = r.num(rm, "resource_length_m", "resource_manager", minimum=10.0)
    points = {}
    for i, pt in enumerate(r.seq(rm.get("points", []), "resource_manager.points")):
        place = f"resource_manager.points[{i}]"
        pm = r.mapping(pt, place)
        points[r.num(pm, "at_m", place)] = (
            r.text(pm, "id", place),
            r.text(pm, "required", place, default="reverse"),
        )
    resources = []
    x, k = 0.0, 1
    while x < length:
        end = min(x + size, length)
        pt_here = [(at, v) for at, v in points.items() if x <= at < end]
        res = Resource(f"R{k}", x, end)
        if pt_here:
            res.point, res.required = pt_here[0][1]
        resources.append(res)
        x, k = end, k + 1
    return resources


def _assertions(r: YamlReader, doc: dict[str, Any], ids: list[str]) -> list[Assertion]:
    assertions = []
    for i, a in enumerate(r.seq(doc.get("assertions", []), "assertions")):
        place = f"assertions[{i}]"
        am = r.mapping(a, place)
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


_TRAIN_KEYS = {
    "id",
    "start_m",
    "length_m",
    "max_speed_kmh",
    "accel_kmhps",
    "service_brake_kmhps",
    "emergency_brake_kmhps",
    "brake_build_up_s",
    "driver_speed_kmh",
    "mode",
    "ato",
    "recovery",
    "safety_distance_m",
    "service_brake",
    "inattentive_until_eb",
    "eb_release_delay_s",
    "tacho_error",
    "missed_tags",
    "depart_at_s",
    "resistance",
}


def _train(r: YamlReader, m: dict[str, Any], place: str) -> TrainConfig:
    r.known(m, _TRAIN_KEYS, place)
    mode = r.text(m, "mode", place, default="atcs")
    if mode not in ("atcs", "ktcs"):
        raise r.fail(f"{place}.mode", f"must be atcs or ktcs, got {excerpt(mode)}")
    sb = r.text(m, "service_brake", place, default="enabled")
    if sb not in ("enabled", "disabled"):
        raise r.fail(f"{place}.service_brake", f"must be enabled or disabled, got {excerpt(sb)}")
    res = r.mapping(m.get("resistance", {}), f"{place}.resistance")
    try:
        params = TrainParams(
            length=r.num(m, "length_m", place, default=200.0, minimum=1.0),
            max_speed=kmh(r.num(m, "max_speed_kmh", place, default=80.0, minimum=1.0)),
            max_traction=kmh(r.num(m, "accel_kmhps", place, default=3.0, minimum=0.1)),
            service_decel=kmh(r.num(m, "service_brake_kmhps", place, default=3.0, minimum=0.1)),
            emergency_decel=kmh(r.num(m, "emergency_brake_kmhps", place, default=4.0, minimum=0.1)),
            brake_build_up=r.num(m, "brake_build_up_s", place, default=1.0, minimum=0.0),
            resistance_a=r.num(res, "a", f"{place}.resistance", default=0.005),
            resistance_b=r.num(res, "b", f"{place}.resistance", default=0.0001),
            resistance_c=r.num(res, "c", f"{place}.resistance", default=0.00002),
        )
    except UsageError as exc:
        raise r.fail(place, str(exc)) from None
    delay = m.get("eb_release_delay_s", 5.0)
    missed = frozenset(
        int(r.value(x, f"{place}.missed_tags[{i}]", minimum=0))
        for i, x in enumerate(r.seq(m.get("missed_tags", []), f"{place}.missed_tags"))
    )
    return TrainConfig(
        train_id=r.text(m, "id", place),
        params=params,
        start=r.num(m, "start_m", place),
        mode=mode,
        driver_speed=kmh(r.num(m, "driver_speed_kmh", place, default=80.0, minimum=0.0)),
        ato=r.flag(m, "ato", place, False),
        recovery=r.flag(m, "recovery", place, False),
        safety_distance=r.num(m, "safety_distance_m", place, default=50.0, minimum=0.0),
        service_brake_enabled=sb == "enabled",
        inattentive_until_eb=r.flag(m, "inattentive_until_eb", place, False),
        eb_release_delay=None
        if delay is None
        else r.num(m, "eb_release_delay_s", place, default=5.0),
        tacho_error=r.num(m, "tacho_error", place, default=0.01, minimum=0.0),
        missed_tags=missed,
        depart_at=r.num(m, "depart_at_s", place, default=0.0, minimum=0.0),
    )
