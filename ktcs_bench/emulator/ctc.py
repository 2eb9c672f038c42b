"""The CTC process: the Type II server feeding the CTC's model, an operator control port
(`ktcs-bench ctc` talks to it) and, when asked, the web console in the same process.

Commands are by object, as an operator thinks: route set/cancel by entry and exit signal, point
normal/reverse, signal stop/release, center/local mode. The operator's desk (`ctc.desk`) turns
each into the CONTROL code of the station's CTC->IXL chart, sends it, and logs the command and its
CONTROL_RESULT (accepted, or the rejection reason) with its time -- the same desk the console's
clicks go through.

With a timetable (the lab file's `ars:`), the CTC runs automatic route setting (`ctc.ars`): ARS
reads the indications after every change the server brings (and at its own deadlines, on the
device's clock: seconds from the CTC's start), and each route it asks for goes out through the
same desk, logged with source "ars"; ARS's log (what it asked for, what came of it, why a train
waits) goes to the device's events and the console's Log panel. The operator
switches it per station (`{"cmd": "ars", "station": N, "on": bool}`, `ktcs-bench ctc ars`, the
console's ARS button); where it is off, routes are set by hand.

Each interval's traffic permission changing hands (SPEC §6.6, read from both its stations'
indications) goes to the device's events (kind `direction`: "interval 1820: permission to 20");
`ktcs-bench ctc direction ST INTERVAL` asks for it like any other command.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from ktcs_bench import kinds
from ktcs_bench import messages as msg
from ktcs_bench.console.server import ConsoleServer
from ktcs_bench.console.trains import TrainPosition, position_from_status
from ktcs_bench.ctc.ars import Ars, ArsLogEntry, ArsRequest
from ktcs_bench.ctc.desk import Desk, Outcome
from ktcs_bench.ctc.model import CtcModel, IntervalWatch, signal_name
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.emulator import variants
from ktcs_bench.emulator.device import Device
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.messages import (
    CTC,
    AddTrain,
    Answer,
    ArsAnswer,
    AskDirection,
    Control,
    ControlAnswer,
    Log,
    LogAnswer,
    Message,
    Mode,
    OperatorCommand,
    Point,
    Refused,
    Route,
    Show,
    ShowAnswer,
    Signal,
    Status,
    TimedAnswer,
    TimedRoute,
)
from ktcs_bench.station.model import Line
from ktcs_bench.station.timetable import Timetable
from ktcs_bench.train.speed_distance import SpeedDistance
from ktcs_bench.transport import jsonlines
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.type2 import events as ev

log = logging.getLogger("ktcs_bench.ctc")


class _Watched:
    """The CTC's indication tables as the server's application, telling `changed` after each
    change the server brings (a link up or down, a full state, indications)."""

    def __init__(self, tables: IndicationTables, changed: Callable[[], None]) -> None:
        self.tables = tables
        self.changed = changed

    def link_up(self, station: int, peer: str) -> None:
        self.tables.link_up(station, peer)
        self.changed()

    def link_down(self, station: int) -> None:
        self.tables.link_down(station)
        self.changed()

    def full_state(self, station: int, items: Sequence[ev.Item]) -> None:
        self.tables.full_state(station, items)
        self.changed()

    def indications(self, station: int, items: Sequence[ev.Item]) -> None:
        self.tables.indications(station, items)
        self.changed()


class RemoteTrains:
    """A TrainSource over train processes (`ktcs-bench emulator train`): each is asked over its
    control port, and computes its curves itself with `endpoint_speed_distance`."""

    def __init__(self) -> None:
        self._addresses: dict[str, tuple[str, int]] = {}

    def add(self, train: str, host: str, port: int) -> None:
        self._addresses[train] = (host, port)

    def train_ids(self) -> list[str]:
        return sorted(self._addresses)

    async def positions(self) -> list[TrainPosition]:
        """Each train's status, asked of all at once; a train that does not answer is left out."""

        async def one(train: str, address: tuple[str, int]) -> TrainPosition | None:
            try:
                answer = await jsonlines.request(*address, Status(), timeout=2.0)
            except (OSError, TimeoutError, ValueError, PeerError):
                return None
            status = answer.get("status")
            if not answer.get("ok") or not isinstance(status, dict):
                return None
            return position_from_status(train, status)

        found = await asyncio.gather(*(one(t, a) for t, a in sorted(self._addresses.items())))
        return [p for p in found if p is not None]

    async def speed_distance(self, train: str) -> SpeedDistance | None:
        address = self._addresses.get(train)
        if address is None:
            return None
        try:
            answer = await jsonlines.request(*address, msg.SpeedDistance(), timeout=5.0)
        except (OSError, TimeoutError, ValueError):
            return None
        data = answer.get("data")
        return SpeedDistance(**data) if answer.get("ok") and isinstance(data, dict) else None


class CtcDevice(Device):
    kind = kinds.CTC
    messages = CTC

    def __init__(
        self,
        name: str,
        line: Line,
        stations: list[int],
        listen: tuple[str, int],
        *,
        allowed_sources: list[str] | None = None,
        control: tuple[str, int] = ("127.0.0.1", 0),
        ssl: Any = None,
        console: tuple[str, int] | None = None,
        console_origins: list[str] | None = None,
        taps: list[str] | None = None,
        faults: frozenset[str] = frozenset(),
        timetable: Timetable | None = None,
        ars_on: Iterable[int] = (),
    ) -> None:
        super().__init__(name, control)
        self.line = line
        self.listen = listen
        self.stations = stations
        self.model = CtcModel(line, stations)
        # automatic route setting, when given a timetable (its clock starts with the device)
        self.ars = Ars(self.model, timetable, ars_on) if timetable is not None else None
        self._ars_tasks: set[asyncio.Task[None]] = set()
        self.intervals = IntervalWatch()  # each interval's permission changing hands, logged
        app = _Watched(self.model.tables, self.indications_changed)
        self.server: CtcServer = variants.ctc_server(
            faults, stations, app,
            allowed_sources=list(allowed_sources) if allowed_sources else None,
            host=listen[0], port=listen[1], ssl=ssl,
        )  # fmt: skip
        self.desk = Desk(self.model, self.server, clock=lambda: self.clock())  # the lab's time
        self.console_address = console
        self.console_origins = console_origins or []
        self.taps = taps or []
        self.console: ConsoleServer | None = None
        self.remote_trains: RemoteTrains | None = None

    # -- operator commands -----------------------------------------------------------------------
    async def handle(self, message: Message) -> Answer:
        match message:
            case Show(station=station):
                try:
                    st = self.model.station(station).number
                except UsageError as exc:
                    return Refused(error=str(exc))
                return ShowAnswer(summary=self.model.summary(st), state=self.model.named(st))
            case Log(last=last):
                return LogAnswer(log=self.desk.log.last(last))
            case Route() | Point() | Signal() | Mode() | AskDirection() | Control():
                return await self.operate(message)
            case msg.Ars():
                return self.ars_command(message)
            case TimedRoute():
                return await self.timed_route(message)
            case AddTrain(train=train, control=control):  # a train process the console may draw
                if self.remote_trains is None:
                    return Refused(error="this CTC serves no console")
                host, _, port = control.rpartition(":")
                self.remote_trains.add(train, host, int(port))
                return Answer()
        return await super().handle(message)

    async def operate(self, command: OperatorCommand) -> ControlAnswer | Refused:
        outcome = await self.carry_out(command, kinds.CTC)
        action = outcome.action
        if action is None or not outcome.answered:  # refused by the CTC, or no answer
            return Refused(error=str(outcome.why))
        return ControlAnswer(ok=outcome.accepted, code=action.name, result=outcome.result,
                             reason=outcome.reason)  # fmt: skip

    async def carry_out(self, command: OperatorCommand, source: str) -> Outcome:
        """One command through the desk (`source`: who gives it), its outcome in the events."""
        outcome = await self.desk.operate(command, source)
        action = outcome.action
        if action is not None and outcome.answered:
            by = "" if source == kinds.CTC else f" (by {source.upper()})"
            self.note("control", f"station {action.station} {action.name}={action.value}{by}: "
                      f"{outcome.result}")  # fmt: skip
        return outcome

    def indications_changed(self) -> None:
        """The server brought a change: log each interval's permission changing hands, and let
        ARS look."""
        for text in self.intervals.update(self.model.intervals()):
            self.note("direction", text)
        self.ars_update()

    # -- automatic route setting -----------------------------------------------------------------
    def ars_state(self) -> dict[str, bool] | None:
        """Station -> ARS on (None: this CTC runs no timetable)."""
        return None if self.ars is None else {str(k): v for k, v in self.ars.enabled.items()}

    def switch_ars(self, station: object, on: bool) -> list[int]:
        """ARS on or off at `station` (None: every station); the stations switched. UsageError
        when this CTC runs no timetable or does not serve the station."""
        if self.ars is None:
            raise UsageError("this CTC runs no timetable: ARS needs `ars:` in the lab file")
        stations = sorted(self.ars.enabled) if station is None else [station]
        done = []
        for st in stations:
            number = self.model.station(st).number
            self.ars.switch(number, on, self._ars_now())
            done.append(number)
        self.ars_update()
        return done

    def ars_command(self, ars: msg.Ars) -> Answer:
        """{"cmd": "ars"}: the state and the last `last` log entries; with "on": true/false
        (and "station", else every station) switch it first."""
        if self.ars is None:
            return Refused(error="this CTC runs no timetable: ARS needs `ars:` in the lab file")
        if ars.on is not None:
            try:
                self.switch_ars(ars.station, ars.on)
            except UsageError as exc:
                return Refused(error=str(exc))
        return ArsAnswer(ars=self.ars.status(), log=self.ars.last(ars.last))

    def _ars_now(self) -> float:
        """ARS's time: seconds since the device started (the timetable's times count from it)."""
        return self.timer.now() if self.timer is not None else 0.0

    def ars_update(self) -> None:
        """The indications changed (or ARS was switched): let ARS look, send what it asks for."""
        if self.ars is None or self.timer is None:
            return
        now = self._ars_now()
        self._ars_send(now, self.ars.update(now))

    def _ars_send(self, now: float, requests: list[ArsRequest]) -> None:
        for request in requests:
            task = asyncio.get_running_loop().create_task(self._ars_request(request))
            self._ars_tasks.add(task)
            task.add_done_callback(self._ars_tasks.discard)
        self.poke()

    async def _ars_request(self, request: ArsRequest) -> None:
        assert self.ars is not None
        outcome = await self.carry_out(request.command, "ars")
        self.ars.result(request, outcome.accepted, outcome.why, self._ars_now())
        self.ars_update()

    def _ars_logged(self, entry: ArsLogEntry) -> None:
        self.note("ars", entry["text"])
        if self.console is not None:
            self.console.note_ars(entry)

    async def timed_route(self, timed: TimedRoute) -> Answer:
        """Set a route and time, in this process's clock, CONTROL sent -> CONTROL_RESULT -> the
        entry signal's proceed indication (the benchmark's end-to-end figure)."""
        model = self.model.station(timed.station)
        entry = signal_name(timed.entry)
        t0 = time.monotonic()
        route = Route(station=timed.station, entry=timed.entry, exit=timed.exit)
        answer = await self.operate(route)
        t_result = time.monotonic() - t0
        if not isinstance(answer, ControlAnswer) or not answer.ok:
            return answer
        await self.server.wait_until(
            lambda: model.proceed_shown(entry, self.model.state(model.number)), timed.timeout
        )
        return TimedAnswer(code=answer.code, result=answer.result, reason=answer.reason,
                           result_s=t_result, proceed_s=time.monotonic() - t0)  # fmt: skip

    # -- life cycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        await super().start()
        if self.ars is not None:  # its zero is now: the timetable counts from the CTC's start
            self.ars.on_log = self._ars_logged
            self.drive(self.ars, self._ars_send, origin=self.now())
        await self.server.start()
        self.ready_info["listen"] = f"{self.listen[0]}:{self.server.port}"
        if self.console_address is not None:  # the web console (seed 004 Fig. 8), same process
            host, port = self.console_address
            self.remote_trains = RemoteTrains()
            self.console = ConsoleServer(
                self.desk,
                taps=self.taps,
                trains=self.remote_trains,
                host=host,
                port=port,
                origins=self.console_origins,
                token=self.token,
                ars=self if self.ars is not None else None,
            )
            await self.console.start()
            if self.ars is not None:  # what ARS logged before the console was up
                for entry in self.ars.last(len(self.ars.log)):
                    self.console.note_ars(entry)
            self.ready_info["console"] = self.console.url

    async def close(self) -> None:
        if self.console is not None:
            await self.console.close()
        for task in list(self._ars_tasks):
            task.cancel()
        await asyncio.gather(*self._ars_tasks, return_exceptions=True)
        await self.server.close()
        await super().close()

    def status(self) -> dict[str, Any]:
        return {**super().status(),
                "stations": {st: self.model.summary(st) for st in self.stations},
                "ars": None if self.ars is None else self.ars.status()}  # fmt: skip
