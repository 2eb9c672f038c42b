"""The CTC's operator model: what a station's indications mean to the operator, and the operator's
commands as control codes (pure: no sockets, no clock).

`StationModel` pairs one station's data with its two Type II code charts, both derived from the
station data (`station_codes.stations.station_chart`, as the IXL derives its own), and reads an
indication table once (`read`) into mode, routes, track circuits, points, signals and traffic
directions. Two renderings of that one reading: `picture` (what the web console draws) and
`summary` (what `ktcs-bench ctc show` and `lab status` print).

An interval's traffic permission (SPEC §6.6) is read from both its stations' tables together
(`CtcModel.interval`): the direction each end indicates (TDU/TDD), which end holds the
permission (PHI) and which asks for it (PRQ). `IntervalWatch` turns successive readings into the
sentences the CTC's log carries ("interval 1820: permission to 20"). Operator commands become `Action`s:
chart code, value, and the sentence the console shows. `CtcModel` holds one per station of the
line, over the CTC's `IndicationTables`.

A track circuit shows "locked" while a route whose track circuits (or overlap) include it reports
RSI (set and locked): the IXL->CTC chart carries route locking per route, not per track circuit,
so sections already released one by one behind a train stay shown locked until the route is.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, NotRequired, TypedDict

from ktcs_bench.ctc.tables import IndicationTable, IndicationTables
from ktcs_bench.errors import UsageError
from ktcs_bench.messages import (
    AskDirection,
    Control,
    Mode,
    OperatorCommand,
    Point,
    Route,
    Signal,
)
from ktcs_bench.station.model import Interval, Line, Station, StationView
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.chart import CodeChart
from ktcs_bench.station_codes.stations import station_chart

UNKNOWN = "unknown"  # what the CTC does not know now (link down, no full state yet, no indication)
# a point's indications, in the order they are read: the first one on gives its position
POINT_INDICATIONS: tuple[tuple[Callable[[int, str], str], str], ...] = (
    (n.sni, "normal"), (n.sri, "reverse"), (n.snr, "to_reverse"), (n.srn, "to_normal"),
)  # fmt: skip


def signal_name(text: str) -> str:
    """Operators write S1, S01 or 01; station data names signals "01"."""
    s = str(text).strip().upper().lstrip("S")
    return s.zfill(2) if s.isdigit() else s


@dataclass(frozen=True)
class Action:
    """One CONTROL for an operator command: chart code name and number, value, and a sentence."""

    station: int
    name: str
    code: int
    value: int
    text: str  # "station 18: set route 01-11"


@dataclass(frozen=True)
class PointReading:
    position: str  # normal, reverse, to_reverse, to_normal, failed (no detection) or unknown
    locked: bool


@dataclass(frozen=True)
class SignalReading:
    aspect: str | None  # None: no aspect indicated
    held: bool
    lamp_failed: bool


@dataclass(frozen=True)
class StationReading:
    """One indication table read once. None wherever the table holds no indication."""

    mode: str | None  # "center" (CTC) or "local" (LOC)
    center_requested: bool  # CMR: center mode asked, awaiting the local operator
    routes_set: frozenset[str]  # RSI
    approach_locked: frozenset[str]  # ALI
    track_circuits: dict[str, bool | None]  # occupied
    points: dict[str, PointReading]
    signals: dict[str, SignalReading]
    directions: dict[str, str | None]  # interval -> "up" / "down" / None
    # interval -> (this end holds the permission: PHI, it asks for it: PRQ); None where the
    # table holds no such indication
    permission: dict[str, tuple[bool | None, bool | None]] = field(default_factory=dict)


@dataclass(frozen=True)
class IntervalReading:
    """One interval's traffic direction as the CTC reads it from both its stations' tables.

    `direction`: "up" / "down" (both ends that are known agree, or one end is known), None (no
    end indicates one), "disagree" (the two ends indicate opposite directions). `holder`: the
    station that indicates it holds the permission (PHI); for a lab-edge (boundary) interval, the
    station outside the lab its fixed direction comes from; None when no end holds it (in transit,
    lost, or not known). `holders`: every end that claims it (two is a fault to show).
    `asking`: the ends that ask for it (PRQ). `known`: the ends whose tables the CTC knows."""

    name: str
    west: int
    east: int
    boundary: bool
    direction: str | None
    holder: int | None
    holders: tuple[int, ...]
    asking: tuple[int, ...]
    known: tuple[int, ...]

    @property
    def departs_from(self) -> int | None:
        """The end trains may depart from into the interval, by its direction (None: neither)."""
        if self.direction == "up":
            return self.west
        if self.direction == "down":
            return self.east
        return None

    @property
    def text(self) -> str:
        """As `ctc show` prints it: `1820  18 ──▶ 20  (held by 18)`, `no direction`, `asked by`."""
        arrow = {"up": "──▶", "down": "◀──"}.get(self.direction or "", "───")
        out = f"{self.name}  {self.west} {arrow} {self.east}"
        if not self.known:
            return out + "  unknown (no indications from either end)"
        notes = []
        if self.direction == "disagree":
            notes.append("the ends disagree")
        elif self.direction is None:
            notes.append("no direction")
        if len(self.holders) > 1:
            notes.append(f"held by both {self.west} and {self.east}")
        elif self.holder is not None:
            outside = "" if self.holder in self.known else ", outside the lab"
            notes.append(f"(held by {self.holder}{outside})")
        elif self.direction is not None:
            notes.append("no holder")
        if self.asking:
            notes.append("asked by " + " and ".join(map(str, self.asking)))
        return out + "  " + ", ".join(notes)

    def summary(self) -> IntervalSummary:
        return {
            "interval": self.name,
            "west": self.west,
            "east": self.east,
            "direction": self.direction,
            "holder": self.holder,
            "asking": list(self.asking),
            "text": self.text,
        }


class IntervalSummary(TypedDict):
    """An interval as `ctc show` (JSON) and the console carry it (`IntervalReading.summary`)."""

    interval: str
    west: int
    east: int
    direction: str | None
    holder: int | None
    asking: list[int]
    text: str


class RoutePicture(TypedDict):
    entry: str
    exit: str
    set: bool
    approach_locked: bool


class TrackCircuitPicture(TypedDict):
    occupied: bool | None
    locked: bool


class PointPicture(TypedDict):
    position: str
    moving: bool
    locked: bool


class SignalPicture(TypedDict):
    kind: str
    aspect: str | None
    held: bool
    lamp_failed: bool


class StationPicture(TypedDict):
    """A station as the web console draws it (`StationModel.picture`)."""

    station: int
    name: str
    connected: bool
    synced: bool
    mode: str
    track_circuits: dict[str, TrackCircuitPicture]
    points: dict[str, PointPicture]
    signals: dict[str, SignalPicture]
    routes: dict[str, RoutePicture]
    directions: dict[str, str | None]
    intervals: NotRequired[dict[str, IntervalSummary]]  # both ends read together (`CtcModel`)


class StationSummary(TypedDict):
    """A station as `ktcs-bench ctc show` prints it (`StationModel.summary`)."""

    station: int
    link: str
    synced: bool
    known: bool
    mode: str
    center_requested: bool
    routes: list[str]
    points: dict[str, str]
    signals: dict[str, str]
    occupied: list[str]
    intervals: NotRequired[dict[str, IntervalSummary]]  # both ends read together (`CtcModel`)


class StationModel:
    """One station as the CTC operator sees and commands it. See the module docstring."""

    def __init__(self, view: StationView) -> None:
        self.view = view
        self.station: Station = view.station
        self.number = view.number
        self.indications: CodeChart = station_chart(view, "ixl_to_ctc")
        self.controls: CodeChart = station_chart(view, "ctc_to_ixl")

    # ------------------------------------------------------------------ indications

    def _reader(self, state: Mapping[int, int]) -> Callable[[str], int | None]:
        """name -> the state the table holds for that indication code (None: none)."""
        chart = self.indications

        def get(name: str) -> int | None:
            try:
                return state.get(chart.number_of(name))
            except KeyError:
                return None

        return get

    def read(self, state: Mapping[int, int]) -> StationReading:
        """The one decoding of an indication table (code number -> state)."""
        get, st = self._reader(state), self.number

        points = {}
        for p in self.station.points:
            position = "failed" if get(n.sfi(st, p.name)) else UNKNOWN
            for code, label in POINT_INDICATIONS:
                if get(code(st, p.name)):
                    position = label
                    break
            points[p.name] = PointReading(position, bool(get(n.sli(st, p.name))))
        signals = {}
        for s in self.station.signals:
            shown = [a for a in s.aspects if get(n.asp(st, s.name, a))]
            signals[s.name] = SignalReading(
                shown[0] if shown else None,
                bool(get(n.ssi(st, s.name))) if s.has_lamps else False,
                bool(get(n.lfi(st, s.name))) if s.has_lamps else False,
            )
        directions: dict[str, str | None] = {}
        permission: dict[str, tuple[bool | None, bool | None]] = {}
        for iv in self.view.intervals:
            directions[iv.name] = (
                "up" if get(n.tdu(iv.name)) else "down" if get(n.tdd(iv.name)) else None
            )
            holds, asks = get(n.phi(iv.name)), get(n.prq(iv.name))
            permission[iv.name] = (
                None if holds is None else bool(holds),
                None if asks is None else bool(asks),
            )
        occupied = {tc.name: get(tc.name) for tc in self.view.track_circuits}
        return StationReading(
            mode="center" if get(n.ctc(st)) else "local" if get(n.loc(st)) else None,
            center_requested=bool(get(n.cmr(st))),
            routes_set=frozenset(r.name for r in self.station.routes if get(n.rsi(st, r.name))),
            approach_locked=frozenset(
                r.name for r in self.station.routes if get(n.ali(st, r.name))
            ),
            track_circuits={k: None if v is None else bool(v) for k, v in occupied.items()},
            points=points,
            signals=signals,
            directions=directions,
            permission=permission,
        )

    def named(self, state: Mapping[int, int]) -> dict[str, int]:
        """The table with code names for numbers (a number the chart does not have stays one)."""
        chart = self.indications
        return {chart.name_of(code) or str(code): v for code, v in state.items()}

    def picture(self, state: Mapping[int, int], connected: bool, synced: bool) -> StationPicture:
        """The station as the web console draws it; what is not indicated reads None / unknown."""
        r = self.read(state)
        mode = "center" if r.mode == "center" else "requested" if r.center_requested else r.mode
        locked_tcs: set[str] = set()
        routes: dict[str, RoutePicture] = {}
        for route in self.station.routes:
            rset = route.name in r.routes_set
            routes[route.name] = {"entry": route.entry, "exit": route.exit, "set": rset,
                                  "approach_locked": route.name in r.approach_locked}  # fmt: skip
            if rset:
                locked_tcs.update(route.all_track_circuits)
        return {
            "station": self.number,
            "name": self.station.name,
            "connected": connected,
            "synced": synced,
            "mode": mode or UNKNOWN,
            "track_circuits": {
                tc: {"occupied": occ, "locked": tc in locked_tcs}
                for tc, occ in r.track_circuits.items()
            },
            "points": {
                p: {
                    "position": pr.position,
                    "moving": pr.position.startswith("to_"),
                    "locked": pr.locked,
                }  # fmt: skip
                for p, pr in r.points.items()
            },
            "signals": {
                s.name: {
                    "kind": s.kind,
                    "aspect": r.signals[s.name].aspect,
                    "held": r.signals[s.name].held,
                    "lamp_failed": r.signals[s.name].lamp_failed,
                }  # fmt: skip
                for s in self.station.signals
            },
            "routes": routes,
            "directions": r.directions,
        }

    def summary(self, table: IndicationTable | None) -> StationSummary:
        """Mode, routes, points, signals, occupancy and link, as `ktcs-bench ctc show` prints them.

        The CTC knows them only while the link is up and has brought a full state: otherwise
        (`known` false) mode, points and signals read "unknown" and no route or occupied track
        circuit is listed -- never the last ones seen, which may no longer hold."""
        lamps = self.station.lamp_signals
        if table is None or not table.known:
            return {
                "station": self.number,
                "link": "up" if table is not None and table.connected else "down",
                "synced": False,
                "known": False,
                "mode": UNKNOWN,
                "center_requested": False,
                "routes": [],
                "points": {p.name: UNKNOWN for p in self.station.points},
                "signals": {s.name: UNKNOWN for s in lamps},
                "occupied": [],
            }
        r = self.read(table.state)
        return {
            "station": self.number,
            "link": "up",
            "synced": True,
            "known": True,
            "mode": r.mode or UNKNOWN,
            "center_requested": r.center_requested,
            "routes": sorted(r.routes_set),
            "points": {
                p: pr.position + (" locked" if pr.locked else "") for p, pr in r.points.items()
            },
            "signals": {s.name: r.signals[s.name].aspect or UNKNOWN for s in lamps},
            "occupied": sorted(tc for tc, occ in r.track_circuits.items() if occ),
        }

    def proceed_shown(self, signal: str, state: Mapping[int, int]) -> bool:
        """Signal `signal` shows a proceed aspect (not merely "R" no longer shown)."""
        get, name = self._reader(state), signal_name(signal)
        aspects = self.station.signal(name).aspects
        return any(get(n.asp(self.number, name, a)) for a in aspects if a != "R")

    # ------------------------------------------------------------------ commands -> controls

    def _action(self, name: str, text: str, value: int = 1) -> Action:
        try:
            code = self.controls.number_of(name)
        except KeyError:
            raise UsageError(f"station {self.number}: no control {name} in the chart") from None
        return Action(self.number, name, code, value, text)

    def route_between(self, entry: str, exit_: str) -> str:
        entry, exit_ = signal_name(entry), signal_name(exit_)
        for r in self.station.routes:
            if r.entry == entry and r.exit == exit_:
                return r.name
        raise UsageError(f"station {self.number}: no route from signal {entry} to {exit_}")

    def set_route(self, entry: str, exit_: str) -> Action:
        route = self.station.route(self.route_between(entry, exit_))
        return self._action(
            n.rsc(self.number, route.name),
            f"station {self.number}: set route {route.entry}-{route.exit}",
        )

    def cancel_route(
        self, entry: str, state: Mapping[int, int], exit_: str | None = None
    ) -> Action:
        """Cancel the route from signal `entry` to `exit_`; without `exit_`, the one from `entry`
        that reports RSI (set)."""
        if exit_ is not None:
            route = self.station.route(self.route_between(entry, exit_))
        else:
            entry = signal_name(entry)
            candidates = [r for r in self.station.routes if r.entry == entry]
            if not candidates:
                raise UsageError(f"station {self.number}: no route starts at signal {entry}")
            set_now = self.read(state).routes_set
            found = [r for r in candidates if r.name in set_now]
            if not found:
                raise UsageError(f"station {self.number}: no route is set from signal {entry}")
            route = found[0]
        return self._action(
            n.rcc(self.number, route.name),
            f"station {self.number}: cancel route {route.entry}-{route.exit}",
        )

    def move_point(self, point: str, position: str) -> Action:
        if point not in {p.name for p in self.station.points}:
            raise UsageError(f"station {self.number}: no point {point}")
        if position not in ("normal", "reverse"):
            raise UsageError(f"point position must be normal or reverse, not {position!r}")
        fn = n.snc if position == "normal" else n.src
        return self._action(
            fn(self.number, point), f"station {self.number}: point {point} to {position}"
        )

    def signal(self, signal: str, action: str) -> Action:
        """Hold signal `signal` at stop ("stop", SSC=1) or release it ("release", SSC=0)."""
        name = signal_name(signal)
        if name not in {s.name for s in self.station.lamp_signals}:
            raise UsageError(f"station {self.number}: no signal {name}")
        if action not in ("stop", "release"):
            raise UsageError(f"signal action must be stop or release, not {action!r}")
        return self._action(
            n.ssc(self.number, name),
            f"station {self.number}: signal {name} {action}",
            1 if action == "stop" else 0,
        )

    def mode(self, wanted: str) -> Action:
        if wanted == "center":
            return self._action(n.cmq(self.number), f"station {self.number}: request center mode")
        if wanted == "local":
            return self._action(n.lmq(self.number), f"station {self.number}: hand back to local")
        raise UsageError(f"mode must be center or local, not {wanted!r}")

    def ask_direction(self, interval: str) -> Action:
        """Ask the neighbour for `interval`'s traffic permission (DRC{interval}=1), ahead of a
        departure route into it."""
        name = str(interval).strip()
        ivs = {iv.name: iv for iv in self.view.intervals}
        if name not in ivs:
            have = ", ".join(ivs) or "none"
            raise UsageError(f"station {self.number}: no interval {name} here (its: {have})")
        if ivs[name].boundary:
            raise UsageError(
                f"station {self.number}: interval {name} is at the lab's edge: its direction "
                "is fixed, there is no neighbour to ask"
            )
        return self._action(
            n.drc(name), f"station {self.number}: ask for the permission of interval {name}"
        )

    def control(self, name: str, value: int = 1) -> Action:
        """Any CTC->IXL code of the chart, by name."""
        return self._action(name, f"station {self.number}: control {name}={value}", value)


class CtcModel:
    """The CTC operator's model of every station of `line` it serves, over its indication tables.

    `stations`: the station numbers of the CTC (default: every station of the line); the tables
    the Type II server feeds are `tables`.
    """

    def __init__(self, line: Line, stations: Iterable[int] | None = None) -> None:
        self.line = line
        numbers = sorted(line.stations if stations is None else stations)
        self.tables = IndicationTables(numbers)
        self.models: dict[int, StationModel] = {
            st: StationModel(line.view(st)) for st in numbers if st in line.stations
        }
        self._read: dict[int, tuple[int, StationReading]] = {}  # station -> (version, reading)

    def reading(self, station: int) -> StationReading | None:
        """Station `station`'s table read (again only when it changed); None while the CTC does
        not know it (link down, no full state yet) or does not serve it."""
        table, model = self.table(station), self.models.get(station)
        if table is None or model is None or not table.known:
            return None
        cached = self._read.get(station)
        if cached is None or cached[0] != table.version:
            cached = self._read[station] = (table.version, model.read(table.state))
        return cached[1]

    def station(self, station: object) -> StationModel:
        """The model of station `station` (a number or its digits); UsageError if not served."""
        try:
            return self.models[int(str(station))]
        except (KeyError, ValueError):
            served = ", ".join(map(str, self.models))
            raise UsageError(f"station {station} is not in this lab ({served})") from None

    def table(self, station: int) -> IndicationTable | None:
        return self.tables.stations.get(station)

    def state(self, station: int) -> Mapping[int, int]:
        table = self.table(station)
        return table.state if table is not None else {}

    def picture(self, station: int) -> StationPicture:
        table = self.table(station)
        model = self.station(station)
        if table is None:
            picture = model.picture({}, False, False)
        else:
            picture = model.picture(table.state, table.connected, table.synced)
        picture["intervals"] = self._interval_summaries(model)
        return picture

    def summary(self, station: int) -> StationSummary:
        model = self.station(station)
        summary = model.summary(self.table(station))
        summary["intervals"] = self._interval_summaries(model)
        return summary

    def _interval_summaries(self, model: StationModel) -> dict[str, IntervalSummary]:
        return {iv.name: self.interval(iv).summary() for iv in model.view.intervals}

    def interval(self, interval: Interval | str) -> IntervalReading:
        """`interval` as the indications of both its stations show it (see `IntervalReading`)."""
        iv = interval if isinstance(interval, Interval) else self._interval(interval)
        ends = {st: r for st in (iv.west, iv.east) if (r := self.reading(st)) is not None}
        return read_interval(iv, ends)

    def intervals(self) -> list[IntervalReading]:
        """Every interval of the line that a station of this CTC borders, in line order."""
        return [self.interval(iv) for iv in self.line.intervals
                if iv.west in self.models or iv.east in self.models]  # fmt: skip

    def _interval(self, name: str) -> Interval:
        for iv in self.line.intervals:
            if iv.name == name:
                return iv
        raise UsageError(f"no interval {name} on line {self.line.name}")

    def named(self, station: int) -> dict[str, int]:
        return self.station(station).named(self.state(station))

    def action(self, command: OperatorCommand | Mapping[str, Any]) -> Action:
        """The Action of one operator command (`messages.OperatorCommand`: route set/cancel, point,
        signal, mode, direction, control), or of its JSON object as the CTC control port takes it
        (read here by `operator_command`). UsageError when it cannot be carried out."""
        if not isinstance(command, Route | Point | Signal | Mode | AskDirection | Control):
            command = operator_command(command)
        model = self.station(command.station)
        try:
            match command:
                case Route(action="set", entry=entry, exit=None):
                    raise UsageError("route command without 'exit'")
                case Route(action="set", entry=entry, exit=str(exit_)):
                    return model.set_route(entry, exit_)
                case Route(entry=entry, exit=exit_):
                    return model.cancel_route(entry, self.state(model.number), exit_)
                case Point(point=point, position=position):
                    return model.move_point(point, position)
                case Signal(signal=signal, action=action):
                    return model.signal(signal, action)
                case Mode(mode=mode):
                    return model.mode(mode)
                case AskDirection(interval=interval):
                    return model.ask_direction(interval)
                case Control(code=code, value=value):
                    return model.control(code, value)
        except ValueError as exc:
            raise UsageError(f"{command.cmd()} command: {exc}") from None
        raise AssertionError(command)


def operator_command(command: Mapping[str, Any]) -> OperatorCommand:
    """An operator command's JSON object (`{"cmd": "route", "action": "set"|"cancel", "station":
    18, "entry": "S1", "exit": "S11"}`, cancel without "exit": the route set from "entry";
    `{"cmd": "point", "position": "normal"|"reverse", "point": "31"}`, `{"cmd": "signal",
    "action": "stop"|"release", "signal": "01"}`, `{"cmd": "mode", "mode": "center"|"local"}`,
    `{"cmd": "direction", "interval": "1820"}`, `{"cmd": "control", "code": "RSC180111",
    "value": 1}`) as its message, read leniently (a
    number where a name is meant is its name). UsageError when it is none of them."""
    cmd = command.get("cmd")
    station = command.get("station")
    at = station if station is None or isinstance(station, int | str) else str(station)
    try:
        if cmd == "route":
            exit_ = command.get("exit")
            action = command.get("action", "set")
            if action not in ("set", "cancel"):
                raise ValueError(f"route action must be set or cancel, not {action!r}")
            return Route(action=action, station=at, entry=str(command["entry"]),
                         exit=None if exit_ is None else str(exit_))  # fmt: skip
        if cmd == "point":
            return Point(station=at, point=str(command["point"]),
                         position=str(command["position"]))  # fmt: skip
        if cmd == "signal":
            return Signal(station=at, signal=str(command["signal"]),
                          action=str(command.get("action", "stop")))  # fmt: skip
        if cmd == "mode":
            return Mode(station=at, mode=str(command["mode"]))
        if cmd == "direction":
            return AskDirection(station=at, interval=str(command["interval"]))
        if cmd == "control":
            return Control(station=at, code=str(command["code"]),
                           value=int(command.get("value", 1)))  # fmt: skip
    except KeyError as exc:
        raise UsageError(f"{cmd} command without {exc}") from None
    except ValueError as exc:
        raise UsageError(f"{cmd} command: {exc}") from None
    raise UsageError(f"unknown command {cmd!r}")


def read_interval(iv: Interval, ends: Mapping[int, StationReading]) -> IntervalReading:
    """`iv` from the readings of whichever of its two stations are known (`ends`)."""
    shown = {ends[st].directions.get(iv.name) for st in ends} - {None}
    direction = shown.pop() if len(shown) == 1 else "disagree" if shown else None
    holders = tuple(st for st in (iv.west, iv.east)
                    if st in ends and ends[st].permission.get(iv.name, (None, None))[0])  # fmt: skip
    asking = tuple(st for st in (iv.west, iv.east)
                   if st in ends and ends[st].permission.get(iv.name, (None, None))[1])  # fmt: skip
    holder = holders[0] if len(holders) == 1 else None
    if not holders and iv.boundary and direction in ("up", "down"):
        # a lab-edge interval: its fixed direction comes from the station outside the lab
        outside = iv.west if direction == "up" else iv.east
        holder = outside if outside not in ends else None
    return IntervalReading(iv.name, iv.west, iv.east, iv.boundary, direction, holder, holders,
                           asking, tuple(sorted(ends)))  # fmt: skip


class IntervalWatch:
    """What changed in each interval's permission between one reading and the next, in the
    words of the CTC's log ("interval 1820: permission to 20"). Pure: fed readings, it returns
    sentences; the first reading of an interval (or one no end is known of) says nothing."""

    def __init__(self) -> None:
        self._last: dict[str, IntervalReading] = {}

    def update(self, readings: Iterable[IntervalReading]) -> list[str]:
        out: list[str] = []
        for r in readings:
            before = self._last.get(r.name)
            if not r.known:
                self._last.pop(r.name, None)
                continue
            self._last[r.name] = r
            if before is None:
                continue
            out += self._changes(before, r)
        return out

    @staticmethod
    def _changes(a: IntervalReading, b: IntervalReading) -> list[str]:
        iv = f"interval {b.name}"
        out = []
        if b.holders != a.holders or b.holder != a.holder:
            if len(b.holders) > 1:
                out.append(f"{iv}: both {b.west} and {b.east} claim the permission")
            elif b.holder is not None:
                out.append(f"{iv}: permission to {b.holder}")
            else:
                gone = f" (was {a.holder})" if a.holder is not None else ""
                out.append(f"{iv}: no end holds the permission{gone}")
        for st in sorted(set(b.asking) - set(a.asking)):
            out.append(f"{iv}: {st} asks for the permission")
        for st in sorted(set(a.asking) - set(b.asking)):
            if b.holder != st:
                out.append(f"{iv}: {st} no longer asks for the permission")
        if b.direction != a.direction and b.direction in ("up", "down", "disagree"):
            if b.direction == "disagree":
                out.append(f"{iv}: the two ends indicate opposite directions")
            else:
                out.append(f"{iv}: direction {b.direction}")
        return out
