"""The reference line for ARS tests in virtual time, no sockets: a real interlocking and trackside
per station (`ixl.rig.StationRig`), the CTC's model whose indication tables hold what each IXL
reports, and `Ars` over them. ARS's requests go as the desk sends them: the model turns each into
its control code, the IXL takes it or refuses it, and ARS learns what came of it. Tests step the
occupancy themselves (a train is the track circuits it occupies)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from ktcs_bench.ctc.ars import Ars, ArsRequest, DirectionRequest, RouteRequest
from ktcs_bench.ctc.model import CtcModel
from ktcs_bench.datafiles import data_dir
from ktcs_bench.ixl.interlocking import ControlResult
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.ixl.routes import RouteStatus
from ktcs_bench.station.loader import load_line
from ktcs_bench.station.model import Line
from ktcs_bench.station.timetable import Timetable, load_timetable
from ktcs_bench.timed.virtual import VirtualClock

LINE = load_line()
REFERENCE = data_dir("emulators") / "timetables" / "reference.yaml"
TIMETABLE = load_timetable(REFERENCE, LINE)


def reference_text() -> str:
    """The reference timetable's text, its `line:` made absolute (to write a variant elsewhere)."""
    text = REFERENCE.read_text(encoding="utf-8")
    return text.replace("line: ../lines/reference.yaml", f"line: {Path(LINE.file).resolve()}")


# the path of an up train from the west edge to station 22 track 1, on the main tracks
UP_MAIN = (
    "TC1851 TC1853A TC1855 TC1857A TC1861A TC1863 TC1867 TC2043 TC2045 TC2047 TC2053A "
    "TC2053B TC2055 TC2057B TC2057A TC2061A TC2063 TC2065 TC2243 TC2245 TC2247 TC2253A "
    "TC2255"
).split()


@dataclass(frozen=True)
class Sent:
    time: float
    request: RouteRequest
    result: ControlResult
    before: RouteStatus  # the route's status in the interlocking when the request came
    ars_on: bool  # ARS was on at the station when it asked


class ArsLine:
    """See the module docstring. `on`: the stations with ARS on at the start."""

    def __init__(
        self,
        on: Iterable[int] = (18, 20, 22),
        timetable: Timetable = TIMETABLE,
        line: Line = LINE,
    ) -> None:
        self.line = line
        self.rigs = {st: StationRig(line.view(st)) for st in sorted(line.stations)}
        self.model = CtcModel(line)
        for st in self.rigs:
            self.model.tables.link_up(st, "rig")
        self.owner = {tc.name: tc.station for tc in line.all_track_circuits()}
        self.clock = VirtualClock()
        self.sent: list[Sent] = []  # the routes ARS asked for
        self.asked: list[tuple[float, DirectionRequest, ControlResult]] = []  # the permissions
        self.hold = False  # True: the CTC's tables stop following the IXLs (a slow link)
        self._pushed: dict[int, dict[str, int]] = {}
        self.sync()
        self.ars = Ars(self.model, timetable, on)
        for rig in self.rigs.values():  # a station's timer may change what it indicates
            self.clock.add(rig, lambda now, _: self.update())
        self.clock.add(self.ars, lambda now, requests: self.send(requests))
        self.update()

    @property
    def now(self) -> float:
        return self.clock.now

    # -- the CTC's view and ARS ----------------------------------------------------------------
    def sync(self) -> None:
        """Every IXL's indications into the CTC's tables, as its full state."""
        if self.hold:
            return
        for st, rig in self.rigs.items():
            if rig.ctc == self._pushed.get(st):
                continue  # unchanged: the table keeps its version (ARS reads it again only if not)
            self._pushed[st] = dict(rig.ctc)
            chart = self.model.station(st).indications
            self.model.tables.full_state(st, [(chart.number_of(k), v) for k, v in rig.ctc.items()])

    def send(self, requests: list[ArsRequest]) -> None:
        for req in requests:
            if isinstance(req, DirectionRequest):  # an interval's permission: asked, not a route
                action = self.model.action(req.command)
                answer = self.rig(req.station).control(action.name, action.value)
                self.asked.append((self.now, req, answer))
                self.sync()
                why = None if answer.accepted else answer.reason.text
                self.ars.result(req, answer.accepted, why, self.now)
                continue
            action = self.model.action(req.command)
            before = self.status(req.station, req.route)
            result = self.rig(req.station).control(action.name, action.value)
            on = self.ars.enabled[req.station]
            self.sent.append(Sent(self.now, req, result, before, on))
            self.sync()
            why = None if result.accepted else result.reason.text
            self.ars.result(req, result.accepted, why, self.now)

    def rig(self, station: int) -> StationRig:
        """Station `station`'s rig, its time brought up to the clock's (before an input)."""
        rig = self.rigs[station]
        rig.handle_timer(self.now)
        return rig

    def update(self) -> None:
        self.sync()
        self.send(self.ars.update(self.now))

    def link(self, station: int, up: bool) -> None:
        """The station's Type II link down (the CTC no longer knows its indications) or up again
        (its full state as it is now)."""
        if up:
            self.model.tables.link_up(station, "rig")
            self._pushed.pop(station, None)
        else:
            self.model.tables.link_down(station)
        self.update()

    def advance(self, seconds: float) -> None:
        """Move virtual time on (`timed.virtual.VirtualClock`: every deadline of the stations and
        of ARS on the way); the stations' own time reaches the end too."""
        end = self.clock.now + seconds
        self.clock.run_until(end)
        for rig in self.rigs.values():
            rig.handle_timer(end)
        self.update()

    # -- the railway ---------------------------------------------------------------------------
    def occupy(self, *tcs: str, occupied: bool = True) -> None:
        for tc in tcs:
            self.rig(self.owner[tc]).occupy(tc, occupied)
        self.update()

    def clear(self, *tcs: str) -> None:
        self.occupy(*tcs, occupied=False)

    def operator(self, station: int, code: str, value: int = 1) -> ControlResult:
        """A control by hand (as `ktcs-bench ctc control ST CODE`)."""
        result = self.rig(station).control(code, value)
        self.update()
        return result

    # -- what to look at -----------------------------------------------------------------------
    def status(self, station: int, route: str) -> RouteStatus:
        return self.rigs[station].ixl.route_status(route)

    def aspect(self, station: int, signal: str) -> str:
        return self.rigs[station].ixl.aspect(signal)

    def requested(self, train: str | None = None) -> list[tuple[int, str]]:
        return [
            (s.request.station, s.request.route)
            for s in self.sent
            if train is None or s.request.train == train
        ]

    def log_text(self) -> str:
        return "\n".join(e["text"] for e in self.ars.log)

    def waiting(self, train: str) -> str | None:
        for t in self.ars.status()["trains"]:
            if t["train"] == train:
                return t["waiting"]  # type: ignore[no-any-return]
        return None

    def move(self, frm: str | None, to: str) -> None:
        """A train's head steps from `frm` into `to`, then its rear clears `frm`."""
        self.occupy(to)
        if frm is not None:
            self.clear(frm)


@dataclass
class RailTrain:
    """A train as the track circuits it occupies, on a fixed path (rear first)."""

    id: str
    path: list[str]
    enters_at: float = 0.0
    footprint: list[str] | None = None  # None: not on the line yet
    head: int = -1  # index in `path` of the head's circuit

    @property
    def done(self) -> bool:
        return self.head == len(self.path) - 1 and self.footprint is not None


class Railway:
    """Trains that step circuit by circuit: each tick a train holding two circuits clears its
    rear, else its head steps on -- unless the circuit ahead is occupied or a signal at stop
    stands between (it waits there, as a driver does)."""

    def __init__(self, bench: ArsLine, trains: list[RailTrain]) -> None:
        self.bench = bench
        self.trains = trains
        self.tcs = {t.name: t for t in bench.line.all_track_circuits()}

    def guard(self, frm: str, to: str) -> tuple[int, str] | None:
        """The lamp signal between two circuits (up direction), as (station, signal)."""
        a = self.tcs[frm]
        for st in self.bench.line.stations.values():
            for s in st.lamp_signals:
                if (
                    s.direction == "up"
                    and abs(s.position_m - a.to_m) < 1e-6
                    and (s.track is None or not a.tracks or s.track in a.tracks)
                ):
                    return st.number, s.name
        return None

    def occupied(self, tc: str) -> bool:
        return self.bench.rigs[self.bench.owner[tc]].occupancy[tc]

    def tick(self, dt: float = 5.0) -> None:
        b = self.bench
        for t in self.trains:
            if t.footprint is None:
                if b.now >= t.enters_at and not self.occupied(t.path[0]):
                    t.footprint, t.head = [t.path[0]], 0
                    b.occupy(t.path[0])
            elif len(t.footprint) == 2:
                b.clear(t.footprint.pop(0))
            elif t.head + 1 < len(t.path):
                nxt = t.path[t.head + 1]
                guard = self.guard(t.path[t.head], nxt)
                if self.occupied(nxt) or (guard is not None and b.aspect(*guard) == "R"):
                    continue
                t.head += 1
                t.footprint.append(nxt)
                b.occupy(nxt)
        b.advance(dt)

    def run(self, until: float) -> None:
        while self.bench.now < until and not all(
            t.done and len(t.footprint or ()) == 1 for t in self.trains
        ):
            self.tick()
