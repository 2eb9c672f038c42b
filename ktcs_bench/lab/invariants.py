"""The safety invariants of the integrated system (issue 15 part 3, SPEC §11), over snapshots of
a running lab.

A `LabSnapshot` is what the devices say at one instant of the lab's clock, read through
`LabAccess` (`snapshot(access)`): where every train is (the track-circuit emulator's ground truth,
not what any interlocking believes), which track circuits the rails report occupied, each IXL's
routes and what they hold, its points, signals, occupancy and the indications it owes the CTC,
each trackside's point machines (where the blades physically are), and the CTC's view of every
station. The checks are plain functions of the snapshot(s) and the line data; nothing here reads
a clock or does I/O.

1. No two trains on one track circuit; no train runs into another (its head beyond the rear of
   the train ahead).
2. No train's front reaches a danger point: it enters a station track circuit only while a locked
   route (its track, or its overlap) holds it -- so the end of the overlap beyond its route's exit
   is where a train must have stopped -- and never reaches the rear of the train ahead.
3. No point moves while a train stands on it or a route over it is locked; no train runs onto a
   point not lying (at rest) where the route holding it needs it.
4. After every fault has cleared and the line has settled: each CTC view equals its IXL's
   indications, and each IXL's occupancy equals the track circuits'.

The rails say themselves when a train trails a point or derails (SPEC §6.7: events
`trailed point ST P`, `derailed ST P` in the track-circuit emulator's log): each counts under 3
(`rails_violation`), read from the log a snapshot carries (`LabSnapshot.rails_events`).

2 and 3 need history (what the head ran onto since the last look, what held a section when a
train entered it): `SafetyChecker` is fed snapshot after snapshot; the lab should be looked at
often enough that a train's head crosses at most a few track-circuit boundaries in between (every
second of lab time is plenty at line speeds).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypedDict

from ktcs_bench import kinds
from ktcs_bench import messages as msg
from ktcs_bench.lab.access import LabAccess
from ktcs_bench.messages import Message
from ktcs_bench.station.model import Line, TrackCircuit
from ktcs_bench.station_codes.stations import station_chart

if TYPE_CHECKING:
    from ktcs_bench.lab.intervals import IntervalGeometry

# Route states in which a route's locked elements protect a train on them: a route being set is
# still throwing its points; an idle route holds nothing.
PROTECTING = frozenset({"set", "entered", "cancelling"})


@dataclass(frozen=True, slots=True)
class TrainState:
    train: str
    head_m: float
    tail_m: float
    track: str = "1"

    @property
    def up(self) -> bool:
        return self.head_m >= self.tail_m

    @property
    def extent(self) -> tuple[float, float]:
        return min(self.head_m, self.tail_m), max(self.head_m, self.tail_m)


@dataclass(frozen=True, slots=True)
class MachineState:
    """A point machine as the trackside has it: where the blades are (None between positions)."""

    position: str | None
    target: str
    moving: bool
    fault: str | None = None


@dataclass(frozen=True)
class StationState:
    """One station: its IXL's state, and its trackside's point machines. A device that did not
    answer (restarting, its link to the lab lost) leaves its part None."""

    station: int
    mode: str | None = None
    links: Mapping[str, bool] | None = None
    routes: Mapping[str, str] | None = None  # route -> status value (idle, setting, set, ...)
    held: Mapping[str, frozenset[str]] | None = None  # route -> track circuits and points held
    startup_held: frozenset[str] = frozenset()  # held by the IXL's start-up locking
    detection: Mapping[str, str] | None = None  # point -> as the IXL reads it
    signals: Mapping[str, str] | None = None  # signal -> commanded aspect
    occupied: frozenset[str] | None = None  # as the IXL takes it
    indications: Mapping[int, int] | None = None  # IXL->CTC code number -> state
    machines: Mapping[str, MachineState] | None = None  # from the trackside
    ctc_view: Mapping[str, int] | None = None  # the CTC's table of this station, by code name
    ctc_known: bool = False  # the CTC has a full state of the station

    @property
    def ixl_known(self) -> bool:
        return self.routes is not None

    def holders(self, element: str, startup_lock: bool = True) -> list[str]:
        """Routes in a protecting state holding `element` (a track circuit or a point), and
        "start-up locking" while the IXL's start-up lock holds it (unless `startup_lock` is
        False: the lock is no route, and a throw the IXL before it began may finish under it)."""
        startup = ["start-up locking"] if startup_lock and element in self.startup_held else []
        if self.routes is None or self.held is None:
            return startup
        return startup + [
            r for r, els in self.held.items() if element in els and self.routes.get(r) in PROTECTING
        ]


RailsEvent = tuple[float, str]
"""An event of the track-circuit emulator's log that an invariant counts: (its time, its text)."""


@dataclass(frozen=True)
class LabSnapshot:
    time: float
    trains: Mapping[str, TrainState]
    occupied: frozenset[str]  # as the rails report it (faults included)
    tc_faults: Mapping[str, str]
    stations: Mapping[int, StationState]
    # the last of the rails' events that are violations (`rails_violation`), oldest first: the
    # checker counts those the look before did not carry
    rails_events: tuple[RailsEvent, ...] = ()


class ViolationJson(TypedDict):
    """A violation as a report writes it (`Violation.to_json`)."""

    invariant: int
    kind: str
    where: str
    time: float
    text: str


@dataclass(frozen=True, slots=True)
class Violation:
    """One broken invariant: which (1-4), what kind, where (a track circuit, point, train or
    station), when (the lab's clock) and a sentence."""

    invariant: int
    kind: str
    where: str
    time: float
    text: str

    def __str__(self) -> str:
        return f"t={self.time:.3f} s invariant {self.invariant} ({self.kind}) at {self.where}: {self.text}"

    def to_json(self) -> ViolationJson:
        return {"invariant": self.invariant, "kind": self.kind, "where": self.where,
                "time": self.time, "text": self.text}  # fmt: skip


# ---------------------------------------------------------------------------------------- geometry


class Geometry:
    """The line as the checks need it: track circuits by name and by track, points by track
    circuit, which station handles what."""

    def __init__(self, line: Line) -> None:
        self.line = line
        self.tcs: tuple[TrackCircuit, ...] = line.all_track_circuits()
        self.tc = {t.name: t for t in self.tcs}
        self.plain = {t.name for t in line.track_circuits}
        self.points_of_tc: dict[str, list[tuple[int, str]]] = {}
        for st in line.stations.values():
            for p in st.points:
                for t in p.track_circuits:
                    self.points_of_tc.setdefault(t, []).append((st.number, p.name))
        self.required: dict[tuple[int, str], dict[str, str]] = {
            (st.number, r.name): {s.point: s.position for s in r.all_points}
            for st in line.stations.values()
            for r in st.routes
        }
        self.station_tcs = {
            n: frozenset(t.name for t in line.view(n).track_circuits) for n in line.stations
        }

    def shunted(self, train: TrainState) -> list[str]:
        """The track circuits a train's axles are in (as the track-circuit emulator sees them)."""
        lo, hi = train.extent
        return [
            t.name for t in self.tcs if lo < t.to_m and hi > t.from_m and t.on_track(train.track)
        ]

    def tc_at(self, position_m: float, track: str, up: bool = True) -> str | None:
        """The track circuit of `track` at a place (its entry end counts, seen running up or
        down)."""
        for t in self.tcs:
            if not t.on_track(track):
                continue
            if (t.from_m <= position_m < t.to_m) if up else (t.from_m < position_m <= t.to_m):
                return t.name
        return None

    def entered(self, before: TrainState, now: TrainState) -> list[str]:
        """The track circuits the head ran into between two looks, in running order."""
        a, b = before.head_m, now.head_m
        if now.up and b > a:
            tcs = [t for t in self.tcs if t.on_track(now.track) and a <= t.from_m < b]
            return [t.name for t in sorted(tcs, key=lambda t: t.from_m)]
        if not now.up and b < a:
            tcs = [t for t in self.tcs if t.on_track(now.track) and b < t.to_m <= a]
            return [t.name for t in sorted(tcs, key=lambda t: -t.to_m)]
        return []


# ---------------------------------------------------------------------------------------- 1


def train_separation(snap: LabSnapshot, geo: Geometry) -> list[Violation]:
    """Invariant 1: no track circuit shunted by two trains; no train's head beyond the rear of
    the train ahead of it on the same track."""
    out: list[Violation] = []
    seen: dict[str, str] = {}
    for name in sorted(snap.trains):
        for tc in geo.shunted(snap.trains[name]):
            if tc in seen:
                out.append(Violation(1, "shared_track_circuit", tc, snap.time,
                                     f"trains {seen[tc]} and {name} both in {tc}"))  # fmt: skip
            else:
                seen[tc] = name
    for a, b in _pairs(snap):
        ta, tb = snap.trains[a], snap.trains[b]
        (alo, ahi), (blo, bhi) = ta.extent, tb.extent
        if alo < bhi and blo < ahi and set(geo.shunted(ta)) & set(geo.shunted(tb)):
            out.append(Violation(1, "collision", f"{a}/{b}", snap.time,
                                 f"train {a} [{alo:.1f}, {ahi:.1f}] m and train {b} "
                                 f"[{blo:.1f}, {bhi:.1f}] m overlap"))  # fmt: skip
    return out


def _pairs(snap: LabSnapshot) -> list[tuple[str, str]]:
    names = sorted(snap.trains)
    return [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]


# ---------------------------------------------------------------------------------------- 2


def danger_points(prev: LabSnapshot | None, snap: LabSnapshot, geo: Geometry) -> list[Violation]:
    """Invariant 2. A train's head may run into a station track circuit only while a route in a
    protecting state (set, entered, cancelling) holds it -- as its own track or as its overlap --
    at the last look or this one: the first station track circuit beyond the protected path (past
    a signal with no route, past the end of an overlap) is a danger point. On the plain line the
    block protects (a train may run on to the rear of the one ahead). Nor may the head reach the
    rear of a train ahead of it on its track."""
    out: list[Violation] = []
    if prev is not None:
        for name, now in sorted(snap.trains.items()):
            before = prev.trains.get(name)
            if before is None or before.track != now.track:
                continue
            for tc in geo.entered(before, now):
                if tc in geo.plain:
                    continue
                st = geo.tc[tc].station
                views = [s.stations.get(st) for s in (prev, snap)]
                if any(v is not None and v.holders(tc) for v in views):
                    continue
                known = any(v is not None and v.ixl_known for v in views)
                why = "no locked route or overlap holds it" if known else "its IXL was not there"
                out.append(Violation(2, "danger_point", tc, snap.time,
                                     f"train {name}'s head ran into {tc} (at {now.head_m:.1f} m): "
                                     f"{why}"))  # fmt: skip
    for a, b in _pairs(snap) + [(b, a) for a, b in _pairs(snap)]:
        ta, tb = snap.trains[a], snap.trains[b]
        rear = geo.tc_at(tb.tail_m, tb.track, tb.up)
        if ta.up != tb.up or rear is None or not geo.tc[rear].on_track(ta.track):
            continue
        ahead = tb.tail_m >= ta.tail_m if ta.up else tb.tail_m <= ta.tail_m
        reached = ta.head_m >= tb.tail_m if ta.up else ta.head_m <= tb.tail_m
        if ahead and reached:
            out.append(Violation(2, "train_rear", f"{a}->{b}", snap.time,
                                 f"train {a}'s head at {ta.head_m:.1f} m reached the rear of "
                                 f"train {b} at {tb.tail_m:.1f} m"))  # fmt: skip
    return out


# ---------------------------------------------------------------------------------------- 3


def point_safety(prev: LabSnapshot | None, snap: LabSnapshot, geo: Geometry) -> list[Violation]:
    """Invariant 3. A point machine between positions while a train is on the point's track
    circuit, or while a route in a protecting state holds the point; a train's head running onto
    a point's track circuit while the point is not at rest in the position the route holding it
    requires."""
    out: list[Violation] = []
    on: dict[str, str] = {}
    for name, t in sorted(snap.trains.items()):
        for tc in geo.shunted(t):
            on.setdefault(tc, name)
    for number, st in sorted(snap.stations.items()):
        for p, m in sorted((st.machines or {}).items()):
            if not m.moving:
                continue
            point = geo.line.station(number).point(p)
            for tc in point.track_circuits:
                if tc in on:
                    out.append(Violation(3, "point_moved_under_train", f"{number}/{p}", snap.time,
                                         f"point {p} of station {number} moving to {m.target} "
                                         f"with train {on[tc]} in {tc}"))  # fmt: skip
            for r in st.holders(p, startup_lock=False):
                status = st.routes.get(r) if st.routes else None
                out.append(Violation(3, "point_moved_locked", f"{number}/{p}", snap.time,
                                     f"point {p} of station {number} moving to {m.target} "
                                     f"while route {r} ({status}) holds it"))  # fmt: skip
    if prev is None:
        return out
    for name, now in sorted(snap.trains.items()):
        before = prev.trains.get(name)
        if before is None or before.track != now.track:
            continue
        for tc in geo.entered(before, now):
            for number, p in geo.points_of_tc.get(tc, []):
                out.extend(_ran_onto(name, tc, number, p, prev, snap, geo))
    return out


def _ran_onto(
    train: str, tc: str, number: int, p: str, prev: LabSnapshot, snap: LabSnapshot, geo: Geometry
) -> list[Violation]:
    st = snap.stations.get(number)
    m = None if st is None or st.machines is None else st.machines.get(p)
    if m is None:
        return []
    routes: list[str] = []
    for s in (prev, snap):
        view = s.stations.get(number)
        routes += [r for r in (view.holders(tc) if view else []) if r not in routes]
    needs = [geo.required.get((number, r), {}) for r in routes]
    wants = {need[p] for need in needs if p in need}
    if m.position is None or m.moving:
        return [Violation(3, "point_not_lying", f"{number}/{p}", snap.time,
                          f"train {train} ran onto point {p} of station {number} (in {tc}) "
                          f"while it moved to {m.target}")]  # fmt: skip
    if wants and m.position not in wants:
        return [Violation(3, "point_wrong_position", f"{number}/{p}", snap.time,
                          f"train {train} ran onto point {p} of station {number} (in {tc}) lying "
                          f"{m.position}; route {'/'.join(routes)} needs {'/'.join(sorted(wants))}")]  # fmt: skip
    return []


def off_the_blades(snap: LabSnapshot, geo: Geometry) -> list[Violation]:
    """Invariant 3, against the rails themselves: a train whose head ran through a point at its
    toe (facing) must be on the leg the blades lie in -- its head on the other leg's track, with
    the blades at rest, is a train run through a point that does not lie for it (what trains
    moved along a booked track, not by the blades, would do)."""
    out: list[Violation] = []
    for name, t in sorted(snap.trains.items()):
        lo, hi = t.extent
        for number, st in sorted(snap.stations.items()):
            for p, m in sorted((st.machines or {}).items()):
                point = geo.line.station(number).point(p)
                if not (lo < point.position_m < hi) or point.side(t.up) != "toe":
                    continue
                if m.moving or m.position not in ("normal", "reverse"):
                    continue
                other = point.reverse if m.position == "normal" else point.normal
                if t.track == other:
                    out.append(Violation(3, "through_point_not_lying", f"{number}/{p}", snap.time,
                                         f"train {name} ran through point {p} of station "
                                         f"{number} lying {m.position} onto track {t.track}"))  # fmt: skip
    return out


RAILS_VIOLATIONS = (
    (re.compile(r"trailed point (\d+) (\S+)"), "trailed_point", "train trailed point {p} of station {st}"),
    (re.compile(r"derailed (\d+) (\S+)"), "derailed", "train derailed at point {p} of station {st}"),
)  # fmt: skip
"""The rails' events that break invariant 3 (SPEC §6.7): what the text starts with (station,
point), the kind, the sentence."""


def rails_violation(time: float, text: str) -> Violation | None:
    """Invariant 3, as the rails report it: a train trailed a point lying against it, or derailed
    on a point whose blades moved or lay between positions under it (None: any other event)."""
    for pattern, kind, sentence in RAILS_VIOLATIONS:
        m = pattern.match(text)
        if m is not None:
            st, p = m.groups()
            return Violation(3, kind, f"{st}/{p}", time, f"{sentence.format(st=st, p=p)}: {text}")
    return None


def rails_events(snap: LabSnapshot, prev: LabSnapshot | None) -> list[Violation]:
    """Invariant 3 from the rails' log: each event in this look's that the last look's did not
    carry."""
    seen = set(prev.rails_events) if prev is not None else set()
    found = [rails_violation(t, text) for t, text in snap.rails_events if (t, text) not in seen]
    return [v for v in found if v is not None]


# ---------------------------------------------------------------------------------------- 4


def views_agree(snap: LabSnapshot, geo: Geometry) -> list[Violation]:
    """Invariant 4, for a settled line with every fault cleared: each CTC view equals the
    indications its IXL owes it, and each IXL's occupancy equals what the rails report for the
    track circuits it handles."""
    out: list[Violation] = []
    for number, st in sorted(snap.stations.items()):
        where = f"station {number}"
        if not st.ixl_known or st.indications is None or st.occupied is None:
            out.append(Violation(4, "ixl_absent", where, snap.time, "its IXL did not answer"))
            continue
        if not st.ctc_known or st.ctc_view is None:
            out.append(Violation(4, "ctc_not_synced", where, snap.time,
                                 "the CTC has no full state of the station"))  # fmt: skip
        else:
            chart = station_chart(geo.line.view(number), "ixl_to_ctc")
            ixl = {chart.name_of(k) or str(k): v for k, v in st.indications.items()}
            differ = sorted(k for k in set(ixl) | set(st.ctc_view)
                            if ixl.get(k) != st.ctc_view.get(k))  # fmt: skip
            if differ:
                shown = ", ".join(f"{k} ixl={ixl.get(k)} ctc={st.ctc_view.get(k)}"
                                  for k in differ[:8])  # fmt: skip
                out.append(Violation(4, "ctc_view", where, snap.time,
                                     f"{len(differ)} indications differ: {shown}"))  # fmt: skip
        rails = snap.occupied & geo.station_tcs[number]
        if st.occupied != rails:
            out.append(Violation(4, "occupancy", where, snap.time,
                                 f"IXL takes {sorted(st.occupied - rails)} occupied and "
                                 f"{sorted(rails - st.occupied)} clear against the rails"))  # fmt: skip
    return out


# ---------------------------------------------------------------------------------------- checker


@dataclass
class SafetyChecker:
    """Invariants 1-3, 5 and 6 (`lab.intervals`) over a lab looked at again and again (`feed`),
    4 on demand (`settled`).
    Every violation found is kept in `violations` as well as returned."""

    line: Line
    geo: Geometry = field(init=False)
    intervals: IntervalGeometry = field(init=False)
    last: LabSnapshot | None = None
    looks: int = 0
    violations: list[Violation] = field(default_factory=list)

    def __post_init__(self) -> None:
        from ktcs_bench.lab import intervals  # invariants 5 and 6; it imports this module

        self.geo = Geometry(self.line)
        self.intervals = intervals.IntervalGeometry(self.line)

    def feed(self, snap: LabSnapshot) -> list[Violation]:
        from ktcs_bench.lab.intervals import interval_direction, opposing_departures

        found = train_separation(snap, self.geo)
        found += danger_points(self.last, snap, self.geo)
        found += point_safety(self.last, snap, self.geo)
        found += rails_events(snap, self.last)
        found += off_the_blades(snap, self.geo)
        found += opposing_departures(snap, self.intervals)
        found += interval_direction(self.last, snap, self.intervals)
        self.last = snap
        self.looks += 1
        self.violations += found
        return found

    def settled(self, snap: LabSnapshot) -> list[Violation]:
        found = self.feed(snap) + views_agree(snap, self.geo)
        self.violations += [v for v in found if v.invariant == 4]
        return found


# ---------------------------------------------------------------------------------------- snapshot


RAILS_LOG = 50
"""How many of the track-circuit emulator's last events a snapshot reads for `rails_violation`
(looks come far more often than that many events)."""


async def snapshot(access: LabAccess, views: bool = True) -> LabSnapshot:
    """What the lab's devices say now, through `LabAccess` (one status request each, the
    track-circuit emulator's last events, and the CTC's `show` per station unless `views` is
    False: invariants 1-3 do not need the CTC's view). A device that does not answer leaves its
    part unknown."""
    device_kinds = access.devices
    time = access.now()
    trains: dict[str, TrainState] = {}
    occupied: set[str] = set()
    tc_faults: dict[str, str] = {}
    logged: list[RailsEvent] = []
    ixls: dict[int, dict[str, Any]] = {}
    sides: dict[int, dict[str, Any]] = {}
    ctcs: list[str] = []
    for name, kind in sorted(device_kinds.items()):
        if kind == kinds.CTC:
            ctcs += [name] if views else []
            continue
        if kind not in (kinds.TRACKCIRCUIT, kinds.IXL, kinds.TRACKSIDE):
            continue
        status = await _status(access, name)
        if status is None:
            continue
        if kind == kinds.TRACKCIRCUIT:
            for t, (head, tail, track) in status.get("trains", {}).items():
                trains[t] = TrainState(t, float(head), float(tail), str(track))
            occupied |= set(status.get("occupied", []))
            tc_faults.update(status.get("faults", {}))
            logged += await _rails_log(access, name)
        elif kind == kinds.IXL:
            ixls[int(status["station"])] = status
        else:
            sides[int(status["station"])] = status
    shown: dict[int, dict[str, Any]] = {}
    for ctc in ctcs:
        status = await _status(access, ctc)
        for number in (status or {}).get("stations", {}):
            answer = await _ask(access, ctc, msg.Show(station=int(number)))
            if answer is not None:
                shown[int(number)] = answer
    stations: dict[int, StationState] = {}
    for number in sorted(set(ixls) | set(sides) | set(shown)):
        ixl, side, view = ixls.get(number), sides.get(number), shown.get(number)
        machines = None
        if side is not None and isinstance(side.get("machines"), dict):
            machines = {p: MachineState(m.get("position"), str(m.get("target")),
                                        bool(m.get("moving")), m.get("fault"))
                        for p, m in side["machines"].items()}  # fmt: skip
        summary = (view or {}).get("summary", {})
        stations[number] = StationState(
            station=number,
            mode=None if ixl is None else ixl.get("mode"),
            links=None if ixl is None else dict(ixl.get("links", {})),
            routes=None if ixl is None else {r: _status_value(s) for r, s in ixl["routes"].items()},
            held=None if ixl is None else {r: frozenset(e) for r, e in ixl.get("held", {}).items()},
            startup_held=frozenset() if ixl is None else frozenset(ixl.get("startup_held", [])),
            detection=None if ixl is None else dict(ixl.get("points", {})),
            signals=None if ixl is None else dict(ixl.get("signals", {})),
            occupied=None if ixl is None else frozenset(ixl.get("occupied", [])),
            indications=None
            if ixl is None
            else {int(k): int(v) for k, v in ixl.get("ctc_state", {}).items()},
            machines=machines,
            ctc_view=None if view is None else dict(view.get("state", {})),
            ctc_known=bool(summary.get("known")) and bool(summary.get("synced")),
        )
    return LabSnapshot(time, trains, frozenset(occupied), tc_faults, stations, tuple(logged))


async def _rails_log(access: LabAccess, name: str) -> list[RailsEvent]:
    """The track-circuit emulator's last events that are violations (`rails_violation`)."""
    answer = await _ask(access, name, msg.Events(last=RAILS_LOG))
    out: list[RailsEvent] = []
    for e in (answer or {}).get("events", []):
        if isinstance(e, dict) and isinstance(e.get("text"), str):
            time, text = float(e.get("time", 0.0)), e["text"]
            if rails_violation(time, text) is not None:
                out.append((time, text))
    return out


def _status_value(text: str) -> str:
    """A route status as the IXL's status prints it ("set", or "RouteStatus.SET")."""
    return text.rpartition(".")[2].lower()


async def _ask(access: LabAccess, name: str, obj: Message) -> dict[str, Any] | None:
    try:
        answer = await access.device(name, obj)
    except (OSError, TimeoutError, ValueError, KeyError):
        return None
    return answer if answer.get("ok") else None


async def _status(access: LabAccess, name: str) -> dict[str, Any] | None:
    answer = await _ask(access, name, msg.Status())
    status = None if answer is None else answer.get("status")
    return status if isinstance(status, dict) else None
