"""Invariants 5 and 6 of the integrated system (SPEC §6.2, §6.6): traffic both ways between
stations, over the same snapshots as `lab.invariants` (fed through its `SafetyChecker`).

5. Two departure routes into one interval from its two ends are never locked at once.
6. No train enters an interval against the direction of a departure route locked into it (from
   the end the train runs towards), and no two trains are in one interval running in opposite
   directions (a train that entered against another one in it).

A route is locked from the moment the IXL locks it until it is idle again (setting, set, entered,
cancelling). `SafetyChecker` (lab.invariants) runs them at every look. Plain functions of the snapshots and the line data; nothing here does I/O.
"""

from __future__ import annotations

from ktcs_bench.lab.invariants import LabSnapshot, TrainState, Violation
from ktcs_bench.station.model import Interval, Line

LOCKED = frozenset({"setting", "set", "entered", "cancelling"})
"""Route states in which a route is locked (not idle)."""


class IntervalGeometry:
    """The intervals of the line and the departure routes into each: interval -> [(station,
    route, direction)]."""

    def __init__(self, line: Line) -> None:
        self.intervals: tuple[Interval, ...] = line.intervals
        self.departures: dict[str, list[tuple[int, str, str]]] = {
            iv.name: [] for iv in self.intervals
        }
        for number in line.stations:
            view = line.view(number)
            for r in view.station.routes:
                iv = view.interval_of_exit(r)
                if iv is not None:
                    self.departures[iv.name].append((number, r.name, r.direction))

    def locked_departures(self, snap: LabSnapshot, interval: str) -> list[tuple[int, str, str]]:
        """The departure routes into `interval` locked in this snapshot (station, route,
        direction); an IXL that did not answer has none."""
        out = []
        for number, route, direction in self.departures[interval]:
            st = snap.stations.get(number)
            if st is not None and st.routes is not None and st.routes.get(route) in LOCKED:
                out.append((number, route, direction))
        return out


def _in(iv: Interval, train: TrainState) -> bool:
    lo, hi = train.extent
    return lo < iv.to_m and hi > iv.from_m


def _head_in(iv: Interval, train: TrainState) -> bool:
    return iv.from_m < train.head_m < iv.to_m


def _direction(train: TrainState) -> str:
    return "up" if train.up else "down"


def opposing_departures(snap: LabSnapshot, geo: IntervalGeometry) -> list[Violation]:
    """Invariant 5: an interval with departure routes locked into it from both of its ends."""
    out: list[Violation] = []
    for iv in geo.intervals:
        locked = geo.locked_departures(snap, iv.name)
        if len({d for _, _, d in locked}) > 1:
            shown = ", ".join(f"{r} of station {n} ({d})" for n, r, d in locked)
            out.append(Violation(5, "opposing_departures", iv.name, snap.time,
                                 f"departure routes into interval {iv.name} locked from both "
                                 f"ends: {shown}"))  # fmt: skip
    return out


def interval_direction(
    prev: LabSnapshot | None, snap: LabSnapshot, geo: IntervalGeometry
) -> list[Violation]:
    """Invariant 6: two trains in one interval facing opposite directions; a train's head
    entering an interval (not in it at the last look, in it now) while a departure route into it
    against the train's direction is locked (at the last look or now)."""
    out: list[Violation] = []
    for iv in geo.intervals:
        inside = sorted((n, t) for n, t in snap.trains.items() if _in(iv, t))
        for i, (a, ta) in enumerate(inside):
            for b, tb in inside[i + 1 :]:
                if ta.up != tb.up:
                    out.append(Violation(6, "opposing_trains", iv.name, snap.time,
                                         f"train {a} ({_direction(ta)}) and train {b} "
                                         f"({_direction(tb)}) in interval {iv.name}"))  # fmt: skip
        if prev is None:
            continue
        against: list[tuple[int, str, str]] = []
        for s in (prev, snap):
            against += [d for d in geo.locked_departures(s, iv.name) if d not in against]
        for name, now in sorted(snap.trains.items()):
            before = prev.trains.get(name)
            if before is None or _head_in(iv, before) or not _head_in(iv, now):
                continue
            for number, route, direction in against:
                if direction != _direction(now):
                    out.append(Violation(6, "entered_against_departure", iv.name, snap.time,
                                         f"train {name} ({_direction(now)}) entered interval "
                                         f"{iv.name} against route {route} of station {number} "
                                         f"({direction}), locked"))  # fmt: skip
    return out
