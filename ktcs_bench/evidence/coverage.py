"""Operation coverage (SPEC §12): what a run exercised, counted per station over everything the
line and the lab have -- each route set, released by a train, cancelled; each point thrown to
normal and to reverse; each aspect of each signal shown; each ATC code sent; each kind of fault
injected. What was never exercised is what an assessor asks about ("the suite never set route
2192"), so every operation of the line is listed, counted or not.

A plain class fed what the bench already records, in order: a procedure's timeline and steps
(`procedure_coverage`, the same for a lab in one process and a live one) and a lab's event log
(`events_coverage`, `lab simulate`'s events.jsonl; `lab_events_coverage` fed as they come, the
whole-system search). Each feed says which categories it observed:
the event log carries no codes, so a run that only read it says nothing of codes.
`coverage.json` is the document; `merge` adds documents up, `never` lists what none exercised.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypedDict

from ktcs_bench import kinds
from ktcs_bench.faults.injector import FAULTS as LINK_FAULTS
from ktcs_bench.lab.topology import Lab
from ktcs_bench.station.model import Line

CATEGORIES = ("routes", "points", "aspects", "codes", "faults")
ROUTE_COUNTS = ("set", "released", "cancelled")
POINT_COUNTS = ("normal", "reverse")
LINE = "line"
"""The key of what belongs to no station (the CTC, the track circuits' emulator, the trains)."""
DEVICE_FAULTS = ("kill", "restart")
POINT_FAULTS = ("detection", "jammed")
RELAY_FAULTS = ("failed_occupied", "failed_clear")
TC_FAULTS = ("failed_occupied", "failed_clear", "no_code")
COVERAGE_FILE = "coverage.json"
FORMAT = "ktcs-bench operation coverage"

Counts = dict[str, Any]  # category -> name -> count, or -> {what: count}


class CoverageJson(TypedDict):
    format: str
    lab: str
    observed: list[str]
    stations: dict[str, Counts]


class OperationCoverage:
    """Counts of one run (or several added up) over the operations of `lab`'s line."""

    def __init__(self, lab: Lab, line: Line | None = None) -> None:
        self.lab = lab
        self.line = line if line is not None else lab.load_line()
        self.observed: set[str] = set()
        self.stations: dict[str, Counts] = {}
        for st in sorted(lab.stations):
            station = self.line.station(st)
            self.stations[str(st)] = {
                "routes": {r.name: dict.fromkeys(ROUTE_COUNTS, 0) for r in station.routes},
                "points": {p.name: dict.fromkeys(POINT_COUNTS, 0) for p in station.points},
                "aspects": {s.name: dict.fromkeys(s.aspects, 0)
                            for s in station.signals if s.aspects},
                "codes": {str(c.code): 0 for c in self.line.speed_codes},
                "faults": {},
            }  # fmt: skip
        for name, dev in lab.devices.items():
            faults = self._faults(self._station_of_device(name))
            for verb in DEVICE_FAULTS:
                faults.setdefault(f"{verb} {dev.kind}", 0)
            if dev.kind == kinds.TRACKSIDE:
                for k in POINT_FAULTS:
                    faults.setdefault(f"point {k}", 0)
                for k in RELAY_FAULTS:
                    faults.setdefault(f"relay {k}", 0)
        for link in lab.links:
            if link.tap:
                for where in self._stations_of_link(link.name):
                    for verb in LINK_FAULTS:
                        self._faults(where).setdefault(f"link {verb}", 0)
        self._tc_station = {tc.name: str(tc.station) if str(tc.station) in self.stations
                            else LINE for tc in self.line.all_track_circuits()}  # fmt: skip
        for where in sorted(set(self._tc_station.values())):
            for k in TC_FAULTS:
                self._faults(where).setdefault(f"tc {k}", 0)
        self._last: dict[str, str] = {}
        self._end: dict[tuple[str, str], str] = {}

    # -- where things are ---------------------------------------------------------------------
    def _faults(self, st: str) -> dict[str, int]:
        if st not in self.stations:
            self.stations.setdefault(LINE, {"faults": {}})
        out: dict[str, int] = self.stations[st]["faults"]
        return out

    def _station_of_device(self, name: str) -> str:
        dev = self.lab.devices.get(name)
        return str(dev.station) if dev is not None and dev.station is not None else LINE

    def _stations_of_link(self, link: str) -> list[str]:
        lk = next((x for x in self.lab.links if x.name == link), None)
        if lk is None:
            return [LINE]
        return sorted({self._station_of_device(lk.a), self._station_of_device(lk.b)})

    def _station_of_tc(self, name: str) -> str:
        return self._tc_station.get(name, LINE)

    def _count(self, st: str, category: str, name: str, what: str | None = None) -> None:
        table = self.stations.get(st, {}).get(category)
        if table is None or name not in table:
            return  # not an operation of this line (a lab of another line's data)
        if what is None:
            table[name] += 1
        elif what in table[name]:
            table[name][what] += 1

    # -- feeds --------------------------------------------------------------------------------
    def route(self, st: int | str, route: str, what: str) -> None:
        """`what`: set, released (by a train) or cancelled."""
        self._count(str(st), "routes", route, what)

    def point(self, st: int | str, point: str, position: str) -> None:
        """A point thrown to `position` (normal or reverse)."""
        self._count(str(st), "points", point, position)

    def aspect(self, st: int | str, signal: str, aspect: str) -> None:
        self._count(str(st), "aspects", signal, aspect)

    def code(self, tc: str, code: str) -> None:
        self._count(self._station_of_tc(tc), "codes", code)

    def fault(self, words: str) -> None:
        """A fault injected, in a procedure's words: `link st18-atc cut`, `point 18 31
        detection`, `relay TC1853A failed_clear`, `tc TC1855 no_code`, `kill ixl20`,
        `restart atc18`."""
        w = words.split()
        if len(w) >= 3 and w[0] == "link":
            if w[2] not in LINK_FAULTS:
                return  # restore, clear: the tap's faults taken off, none injected
            for st in self._stations_of_link(w[1]):
                self._count_fault(st, f"link {w[2]}")
        elif len(w) == 4 and w[0] == "point":
            self._count_fault(w[1], f"point {w[3]}")
        elif len(w) == 3 and w[0] in ("relay", "tc"):
            self._count_fault(self._station_of_tc(w[1]), f"{w[0]} {w[2]}")
        elif len(w) == 2 and w[0] in DEVICE_FAULTS and w[1] in self.lab.devices:
            dev = self.lab.devices[w[1]]
            self._count_fault(self._station_of_device(w[1]), f"{w[0]} {dev.kind}")

    def _count_fault(self, st: str, kind: str) -> None:
        faults = self._faults(st if st in self.stations else LINE)
        faults[kind] = faults.get(kind, 0) + 1

    # -- a procedure's timeline and a lab's events -------------------------------------------------
    _SIGNAL = re.compile(r"^ixl (\d+) signal (\S+)$")
    _POINT = re.compile(r"^ctc (\d+) point (\S+)$")
    _ROUTES = re.compile(r"^ctc (\d+) routes$")
    _CODE = re.compile(r"^code (\S+)$")

    def sample(self, what: str, value: str, cancelled: Iterable[tuple[str, str]] = ()) -> None:
        """One change of a procedure's timeline (`ProcedureResult.timeline`): `cancelled`, the
        (station, route) a CTC cancel was accepted for since the route was set."""
        before = self._last.get(what)
        self._last[what] = value
        if m := self._SIGNAL.match(what):
            self.aspect(m[1], m[2], value)
        elif m := self._CODE.match(what):
            self.code(m[1], value.split()[0] if value.split() else value)
        elif m := self._POINT.match(what):
            end = value.split()[0] if value.split() else ""
            if end in POINT_COUNTS:
                last = self._end.get((m[1], m[2]))
                if last is not None and last != end:
                    self.point(m[1], m[2], end)
                self._end[(m[1], m[2])] = end
        elif m := self._ROUTES.match(what):
            now = set(value.split()) - {"-"}
            was = set((before or "").split()) - {"-"}
            gone = set(cancelled)
            for r in sorted(now - was):
                self.route(m[1], r, "set")
            for r in sorted(was - now):
                self.route(m[1], r, "cancelled" if (m[1], r) in gone else "released")

    _EV_ROUTE = re.compile(r"^route (\S+) (set: points detected|fully released|cancelled and "
                           r"released|released \(timed release\))$")  # fmt: skip
    _EV_POINT = re.compile(r"^point (\S+) commanded (normal|reverse)$")
    _EV_SIGNAL = re.compile(r"^signal (\S+) (\S+)$")

    def event(self, device: str, kind: str, text: str) -> None:
        """One event of a lab's log (events.jsonl: device, kind, text)."""
        dev = self.lab.devices.get(device)
        if kind == "lab" and text == "restarted":  # the lab's own event, whatever the device
            self.fault(f"restart {device}")
        elif dev is not None and dev.kind == kinds.IXL and dev.station is not None:
            st = str(dev.station)
            if kind == "route" and (m := self._EV_ROUTE.match(text)):
                what = {"set: points detected": "set", "fully released": "released"}
                self.route(st, m[1], what.get(m[2], "cancelled"))
            elif kind == "point" and (m := self._EV_POINT.match(text)):
                self.point(st, m[1], m[2])
            elif kind == "signal" and (m := self._EV_SIGNAL.match(text)):
                self.aspect(st, m[1], m[2])
        elif kind == "tap" and text.split():
            self.fault(f"link {device} {text.split()[0]}")

    # -- the document ---------------------------------------------------------------------------
    def as_json(self) -> CoverageJson:
        return {"format": FORMAT, "lab": self.lab.name, "observed": sorted(self.observed),
                "stations": json.loads(json.dumps(self.stations))}  # fmt: skip


def lab_events_coverage(lab: Lab) -> OperationCoverage:
    """A coverage to be fed a lab's events as they come (`event`: the interlockings' routes,
    points and aspects, the lab's own tap faults and restarts), each signal's first aspect
    counted already: every interlocking starts with its signals at stop (SPEC §6.2) and logs an
    aspect only when it changes. The events carry no ATC codes: codes are not observed."""
    cov = OperationCoverage(lab)
    cov.observed.update(("routes", "points", "aspects", "faults"))
    for st, table in cov.stations.items():
        for signal, aspects in table.get("aspects", {}).items():
            if aspects:
                cov.aspect(st, signal, next(iter(aspects)))
    return cov


def events_coverage(lab: Lab, events: Path) -> OperationCoverage:
    """A lab run's coverage from its event log (events.jsonl), as `lab_events_coverage`."""
    cov = lab_events_coverage(lab)
    with events.open(encoding="utf-8") as fh:
        for line in fh:
            try:
                e = json.loads(line)
            except ValueError:
                continue  # a run stopped mid-line
            if isinstance(e, dict):
                cov.event(str(e.get("device")), str(e.get("kind")), str(e.get("text")))
    return cov


def write_coverage(path: Path, cov: OperationCoverage) -> Path:
    """The coverage document written to `path` (its folder made if need be)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(cov.as_json(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return path


def write_events_coverage(out: Path, lab: Lab) -> Path:
    """`out`/coverage.json from `out`/events.jsonl (`lab simulate`)."""
    return write_coverage(out / COVERAGE_FILE, events_coverage(lab, out / "events.jsonl"))


# -- documents added up ------------------------------------------------------------------------------
def is_coverage(doc: object) -> bool:
    return isinstance(doc, dict) and doc.get("format") == FORMAT


def merge(docs: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """Documents (`as_json`) added up: every count summed, the categories any of them observed."""
    observed: set[str] = set()
    stations: dict[str, Any] = {}
    labs: set[str] = set()
    for doc in docs:
        observed.update(doc.get("observed", ()))
        labs.add(str(doc.get("lab")))
        for st, cats in doc.get("stations", {}).items():
            into = stations.setdefault(st, {})
            for cat, table in cats.items():
                _add(into.setdefault(cat, {}), table)
    return {"format": FORMAT, "lab": ", ".join(sorted(labs)), "observed": sorted(observed),
            "stations": stations}  # fmt: skip


def _add(into: dict[str, Any], table: Mapping[str, Any]) -> None:
    for name, value in table.items():
        if isinstance(value, Mapping):
            _add(into.setdefault(name, {}), value)
        elif isinstance(value, int):
            into[name] = int(into.get(name, 0)) + value


def _unset(name: str, v: Any) -> list[str]:
    return [name] if not v.get("set") else []


def _unreversed(name: str, v: Any) -> list[str]:
    return [name] if not v.get("reverse") else []


def _unshown(name: str, v: Any) -> list[str]:
    return [f"{name} {a}" for a, n in v.items() if not n]


def _zero(name: str, v: Any) -> list[str]:
    return [name] if not v else []


NEVER: dict[str, tuple[str, Callable[[str, Any], list[str]]]] = {
    "routes_never_set": ("routes", _unset),
    "points_never_reversed": ("points", _unreversed),
    "aspects_never_shown": ("aspects", _unshown),
    "codes_never_sent": ("codes", _zero),
    "faults_never_injected": ("faults", _zero),
}
"""The findings `never` lists: each a category and what of one entry was never exercised."""


def never(doc: Mapping[str, Any]) -> dict[str, dict[str, list[str]]]:
    """Per finding (`routes_never_set`, ...) each station's list of what no run exercised; a
    category no run observed is left out (nothing is known of it)."""
    observed = set(doc.get("observed", ()))
    out: dict[str, dict[str, list[str]]] = {}
    for key, (cat, pick) in NEVER.items():
        if cat not in observed:
            continue
        found: dict[str, list[str]] = {}
        for st, cats in sorted(doc.get("stations", {}).items()):
            names: list[str] = []
            for name, value in sorted(cats.get(cat, {}).items()):
                names += pick(name, value)
            if cats.get(cat):
                found[st] = names
        out[key] = found
    return out
