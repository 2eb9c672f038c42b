"""The CTC process: the Type II server feeding the CTC's model, an operator control port
(`ktcs-bench ctc` talks to it) and, when asked, the web console in the same process.

Commands are by object, as an operator thinks: route set/cancel by entry and exit signal, point
normal/reverse, signal stop/release, center/local mode. The operator's desk (`ctc.desk`) turns
each into the CONTROL code of the station's CTC->IXL chart, sends it, and logs the command and its
CONTROL_RESULT (accepted, or the rejection reason) with its time -- the same desk the console's
clicks go through.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from ktcs_bench.console.server import ConsoleServer
from ktcs_bench.ctc.desk import Desk
from ktcs_bench.ctc.model import CtcModel, signal_name
from ktcs_bench.emulator import variants
from ktcs_bench.emulator.device import Device
from ktcs_bench.errors import UsageError
from ktcs_bench.station.model import Line
from ktcs_bench.train.speed_distance import SpeedDistance
from ktcs_bench.transport import jsonlines
from ktcs_bench.type2.ctc_server import CtcServer

log = logging.getLogger("ktcs_bench.ctc")


class RemoteTrains:
    """A TrainSource over train processes (`ktcs-bench emulator train`): each is asked over its
    control port, and computes its curves itself with `endpoint_speed_distance`."""

    def __init__(self) -> None:
        self._addresses: dict[str, tuple[str, int]] = {}

    def add(self, train: str, host: str, port: int) -> None:
        self._addresses[train] = (host, port)

    def train_ids(self) -> list[str]:
        return sorted(self._addresses)

    async def speed_distance(self, train: str) -> SpeedDistance | None:
        address = self._addresses.get(train)
        if address is None:
            return None
        try:
            answer = await jsonlines.request(*address, {"cmd": "speed_distance"}, timeout=5.0)
        except (OSError, TimeoutError, ValueError):
            return None
        data = answer.get("data")
        return SpeedDistance(**data) if answer.get("ok") and isinstance(data, dict) else None


class CtcDevice(Device):
    kind = "ctc"

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
    ) -> None:
        super().__init__(name, control)
        self.line = line
        self.listen = listen
        self.stations = stations
        self.model = CtcModel(line, stations)
        self.server: CtcServer = variants.ctc_server(
            faults, stations, self.model.tables,
            allowed_sources=list(allowed_sources) if allowed_sources else None,
            host=listen[0], port=listen[1], ssl=ssl,
        )  # fmt: skip
        self.desk = Desk(self.model, self.server)
        self.console_address = console
        self.console_origins = console_origins or []
        self.taps = taps or []
        self.console: ConsoleServer | None = None
        self.remote_trains: RemoteTrains | None = None

    # -- operator commands -----------------------------------------------------------------------
    async def command(self, obj: dict[str, Any]) -> dict[str, Any]:
        cmd = obj.get("cmd")
        if cmd == "show":
            try:
                st = self.model.station(obj.get("station")).number
            except UsageError as exc:
                return {"ok": False, "error": str(exc)}
            return {"ok": True, "summary": self.model.summary(st), "state": self.model.named(st)}
        if cmd == "log":
            return {"ok": True, "log": self.desk.log.last(int(obj.get("last", 50)))}
        if cmd in ("route", "point", "signal", "mode", "control"):
            return await self.operate(obj)
        if cmd == "timed_route":
            return await self.timed_route(obj)
        if cmd == "add_train":  # a train process the console may draw (the lab tells us)
            if self.remote_trains is None:
                return {"ok": False, "error": "this CTC serves no console"}
            host, _, port = str(obj["control"]).rpartition(":")
            self.remote_trains.add(str(obj["train"]), host, int(port))
            return {"ok": True}
        return await super().command(obj)

    async def operate(self, obj: dict[str, Any]) -> dict[str, Any]:
        outcome = await self.desk.operate(obj, "ctc")
        action = outcome.action
        if action is None or not outcome.answered:  # refused by the CTC, or no answer
            return {"ok": False, "error": outcome.why}
        self.note("control", f"station {action.station} {action.name}={action.value}: "
                  f"{outcome.result}")  # fmt: skip
        return {"ok": outcome.accepted, "code": action.name, "result": outcome.result,
                "reason": outcome.reason}  # fmt: skip

    async def timed_route(self, obj: dict[str, Any]) -> dict[str, Any]:
        """Set a route and time, in this process's clock, CONTROL sent -> CONTROL_RESULT -> the
        entry signal's proceed indication (the benchmark's end-to-end figure)."""
        model = self.model.station(obj["station"])
        entry = signal_name(str(obj["entry"]))
        t0 = time.monotonic()
        answer = await self.operate({**obj, "cmd": "route", "action": "set"})
        t_result = time.monotonic() - t0
        if not answer.get("ok"):
            return answer
        await self.server.wait_until(
            lambda: model.proceed_shown(entry, self.model.state(model.number)),
            float(obj.get("timeout", 30.0)),
        )
        return {**answer, "result_s": t_result, "proceed_s": time.monotonic() - t0}

    # -- life cycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        await super().start()
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
            )
            await self.console.start()
            self.ready_info["console"] = self.console.url

    async def close(self) -> None:
        if self.console is not None:
            await self.console.close()
        await self.server.close()
        await super().close()

    def status(self) -> dict[str, Any]:
        return {**super().status(),
                "stations": {st: self.model.summary(st) for st in self.stations}}  # fmt: skip
