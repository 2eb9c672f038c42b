"""The CTC process: the Type II server holding every station's indication state, an operator
control port (`ktcs-bench ctc` talks to it), and a log of every command and result with its time.

Commands are by object, as an operator thinks: route set/cancel by entry and exit signal, point
normal/reverse, signal stop/release, center/local mode; each becomes the CONTROL code of the
station's CTC->IXL chart, and the CONTROL_RESULT comes back as accepted or the rejection reason.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from ktcs_bench.charts import names as n
from ktcs_bench.charts.generate import station_chart
from ktcs_bench.charts.model import CodeChart
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.emulator import variants
from ktcs_bench.emulator.device import Device
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.station.model import Line
from ktcs_bench.type2.ctc_server import CtcServer

log = logging.getLogger("ktcs_bench.ctc")
CONTROL_TIMEOUT = 10.0
UNKNOWN = "unknown"  # an indication the CTC does not know now (link down, no full state yet)


def _signal(name: str) -> str:
    """Operators write S1, S01 or 01; station data names signals "01"."""
    s = name.strip().upper().lstrip("S")
    return s.zfill(2) if s.isdigit() else s


def command_words(obj: dict[str, Any]) -> str:
    """An operator command as the operator types it to `ktcs-bench ctc` ("route set 18 01 11"),
    for the command log; a command of another shape as its keys and values."""
    cmd, st = str(obj.get("cmd", "?")), obj.get("station", "?")
    if cmd == "route":
        entry, exit_ = _signal(str(obj.get("entry", "?"))), _signal(str(obj.get("exit", "?")))
        return f"route {obj.get('action', 'set')} {st} {entry} {exit_}"
    if cmd == "point":
        return f"point {obj.get('position', '?')} {st} {obj.get('point', '?')}"
    if cmd == "signal":
        return f"signal {obj.get('action', 'stop')} {st} {_signal(str(obj.get('signal', '?')))}"
    if cmd == "mode":
        return f"mode {obj.get('mode', '?')} {st}"
    if cmd == "control":
        return f"control {st} {obj.get('code', '?')} {obj.get('value', 1)}"
    return " ".join([cmd, *(f"{k}={v}" for k, v in obj.items() if k != "cmd")])


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
        taps: list[str] | None = None,
        faults: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(name, control)
        self.line = line
        self.listen = listen
        self.stations = stations
        self.ind: dict[int, CodeChart] = {}
        self.ctl: dict[int, CodeChart] = {}
        for st in stations:
            view = line.view(st)
            self.ind[st] = station_chart(view, "ixl_to_ctc")
            self.ctl[st] = station_chart(view, "ctc_to_ixl")
        self.tables = IndicationTables(stations)
        self.server: CtcServer = variants.ctc_server(
            faults, stations, self.tables, allowed_sources=list(allowed_sources) if allowed_sources else None,
            host=listen[0], port=listen[1], ssl=ssl,
        )  # fmt: skip
        self.command_log: list[dict[str, Any]] = []
        self.console_address = console
        self.taps = taps or []
        self.console: Any = None
        self.remote_trains: Any = None

    # -- state as names ----------------------------------------------------------------------------
    def named(self, st: int) -> dict[str, int]:
        view = self.tables.stations.get(st)
        if view is None:
            return {}
        chart = self.ind[st]
        return {chart.name_of(code) or str(code): v for code, v in view.state.items()}

    def summary(self, st: int) -> dict[str, Any]:
        """Mode, routes, points, signals, occupancy and link of one station, from its indications.

        The CTC knows them only while the link is up and has brought a full state: otherwise
        (`known` false) mode, points and signals read "unknown" and no route or occupied track
        circuit is listed -- never the last ones seen, which may no longer hold."""
        view = self.tables.stations.get(st)
        station = self.line.station(st)
        known = bool(view is not None and view.connected and view.synced)
        if not known:
            return {
                "station": st,
                "link": "up" if view is not None and view.connected else "down",
                "synced": False,
                "known": False,
                "mode": UNKNOWN,
                "center_requested": False,
                "routes": [],
                "points": {p.name: UNKNOWN for p in station.points},
                "signals": {s.name: UNKNOWN for s in station.lamp_signals},
                "occupied": [],
            }
        state = self.named(st)
        on = [k for k, v in state.items() if v]
        points = {}
        for p in station.points:
            pos = ("normal" if state.get(n.sni(st, p.name)) else
                   "reverse" if state.get(n.sri(st, p.name)) else
                   "moving" if state.get(n.snr(st, p.name)) or state.get(n.srn(st, p.name)) else
                   "no detection")  # fmt: skip
            if state.get(n.sli(st, p.name)):
                pos += " locked"
            points[p.name] = pos
        signals = {}
        for s in station.lamp_signals:
            shown = [a for a in s.aspects if state.get(n.asp(st, s.name, a))]
            signals[s.name] = shown[0] if shown else "?"
        return {
            "station": st,
            "link": "up",
            "synced": True,
            "known": True,
            "mode": "center" if state.get(n.ctc(st)) else "local" if state.get(n.loc(st)) else "?",
            "center_requested": bool(state.get(n.cmr(st))),
            "routes": sorted(r.name for r in station.routes if state.get(n.rsi(st, r.name))),
            "points": points,
            "signals": signals,
            "occupied": sorted(k for k in on if k.startswith("TC")),
        }

    # -- operator commands -----------------------------------------------------------------------
    def control_name(self, obj: dict[str, Any]) -> tuple[int, str, int]:
        """(station, CTC->IXL code name, value) for an operator command; KeyError/ValueError if bad."""
        st = int(obj["station"])
        if st not in self.ctl:
            raise ValueError(
                f"station {st} is not in this lab ({', '.join(map(str, self.stations))})"
            )
        station = self.line.station(st)
        cmd = obj["cmd"]
        if cmd == "route":
            entry, exit_ = _signal(str(obj["entry"])), _signal(str(obj["exit"]))
            found = [r for r in station.routes if r.entry == entry and r.exit == exit_]
            if not found:
                raise ValueError(f"station {st} has no route from signal {entry} to {exit_}")
            route = found[0].name
            return (
                st,
                (n.rsc(st, route) if obj.get("action", "set") == "set" else n.rcc(st, route)),
                1,
            )
        if cmd == "point":
            p = str(obj["point"])
            station.point(p)
            return st, (n.snc(st, p) if obj["position"] == "normal" else n.src(st, p)), 1
        if cmd == "signal":
            s = _signal(str(obj["signal"]))
            station.signal(s)
            return st, n.ssc(st, s), 1 if obj.get("action", "stop") == "stop" else 0
        if cmd == "mode":
            return st, (n.cmq(st) if obj["mode"] == "center" else n.lmq(st)), 1
        if cmd == "control":
            return st, str(obj["code"]), int(obj.get("value", 1))
        raise ValueError(f"unknown command {cmd!r}")

    async def command(self, obj: dict[str, Any]) -> dict[str, Any]:
        cmd = obj.get("cmd")
        if cmd == "show":
            st = int(obj["station"])
            return {"ok": True, "summary": self.summary(st), "state": self.named(st)}
        if cmd == "log":
            return {"ok": True, "log": self.command_log[-int(obj.get("last", 50)) :]}
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
        entry: dict[str, Any] = {"time": time.time(), "command": command_words(obj)}
        self.command_log.append(entry)
        try:
            st, code_name, value = self.control_name(obj)
            code = self.ctl[st].number_of(code_name)
        except (KeyError, ValueError) as exc:
            entry["result"] = f"refused by the CTC: {exc}"
            log.warning("command %s refused: %s", entry["command"], exc)
            return {"ok": False, "error": str(exc).strip("'\"")}
        view = self.tables.stations.get(st)
        if view is None or not view.connected:
            entry["result"] = "station link down"
            return {"ok": False, "error": f"station {st} is not connected"}
        t0 = time.monotonic()
        try:
            result = await self.server.control(st, code, value, CONTROL_TIMEOUT)
        except (TimeoutError, ConnectionError) as exc:
            entry["result"] = f"no result: {exc or 'timeout'}"
            return {"ok": False, "error": f"no CONTROL_RESULT from station {st}"}
        reason = Reason(result.reason) if result.reason in Reason._value2member_map_ else None
        text = (
            "accepted"
            if result.accepted
            else f"rejected: {reason.text if reason else result.reason}"
        )
        entry.update(result=text, code=code_name, seconds=round(time.monotonic() - t0, 4))
        log.info("station %d %s=%d -> %s", st, code_name, value, text)
        self.note("control", f"station {st} {code_name}={value}: {text}")
        return {"ok": result.accepted, "code": code_name, "result": text,
                "reason": int(result.reason)}  # fmt: skip

    async def timed_route(self, obj: dict[str, Any]) -> dict[str, Any]:
        """Set a route and time, in this process's clock, CONTROL sent -> CONTROL_RESULT -> the
        entry signal's proceed indication (the benchmark's end-to-end figure)."""
        st = int(obj["station"])
        entry = _signal(str(obj["entry"]))
        aspects = self.line.station(st).signal(entry).aspects
        t0 = time.monotonic()
        answer = await self.operate({**obj, "cmd": "route", "action": "set"})
        t_result = time.monotonic() - t0
        if not answer.get("ok"):
            return answer
        chart = self.ind[st]
        codes = [chart.number_of(n.asp(st, entry, a)) for a in aspects if a != "R"]

        def proceed() -> bool:  # a proceed aspect shown (not merely "R" no longer shown)
            view = self.tables.stations.get(st)
            return view is not None and any(view.state.get(c) == 1 for c in codes)

        await self.server.wait_until(proceed, float(obj.get("timeout", 30.0)))
        return {**answer, "result_s": t_result, "proceed_s": time.monotonic() - t0}

    # -- life cycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        await super().start()
        await self.server.start()
        self.ready_info["listen"] = f"{self.listen[0]}:{self.server.port}"
        if self.console_address is not None:  # the web console (seed 004 Fig. 8), same process
            from ktcs_bench.console.server import ConsoleServer

            host, port = self.console_address
            from ktcs_bench.console.trains import RemoteTrains

            self.remote_trains = RemoteTrains()
            self.console = ConsoleServer(
                self.server, self.tables, self.line, taps=self.taps, trains=self.remote_trains, host=host,
                port=port,
            )  # fmt: skip
            await self.console.start()
            self.ready_info["console"] = self.console.url

    async def close(self) -> None:
        if self.console is not None:
            await self.console.close()
        await self.server.close()
        await super().close()

    def status(self) -> dict[str, Any]:
        return {**super().status(), "stations": {st: self.summary(st) for st in self.stations}}
