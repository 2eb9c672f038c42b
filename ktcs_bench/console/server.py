"""The CTC operator console (seed 004 Fig. 8) as a web page served by the CTC process (aiohttp).

`ConsoleServer` reads the CTC's per-station indication tables (`CtcServer.stations[n].state`),
serves the track diagram and a websocket that pushes the station pictures whenever the CTC's
state changes, and turns the operator's clicks into Type II CONTROLs (`CtcServer.control`) whose
results come back to the page and the log. Side panels: a link monitor over tap control ports
(Fig. 7 console text) and a speed–distance view of a train (`trains.TrainSource`).

Embedding (e.g. in the CTC emulator process, on its event loop):

    console = ConsoleServer(ctc, load_line(), load_charts(ctc.stations), taps=["st18-ctc"])
    await console.start(); print(console.url); ...; await console.close()

It chains itself onto `ctc.on_event` (restored on close) and also re-checks the state every
`POLL_S`, so it needs nothing else from the CTC.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ktcs_bench.charts.model import CodeChart, load_chart
from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.codec.render import to_text
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.console.diagram import build
from ktcs_bench.console.state import Action, StationModel, station_models
from ktcs_bench.console.trains import EndpointTrains, TrainSource
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.station.model import Line
from ktcs_bench.tap.registry import resolve_tap
from ktcs_bench.train.endpoint import TrainEndpoint
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.ctc_server import CtcServer

log = logging.getLogger("ktcs_bench.console")

STATIC = Path(__file__).resolve().parent / "static"
POLL_S = 0.5  # state re-check besides the CTC's events (link state, missed callbacks)
TRAIN_PERIOD_S = 0.5  # speed–distance refresh for a client watching a train
CONTROL_TIMEOUT_S = 5.0  # CONTROL -> CONTROL_RESULT
LOG_KEEP = 300  # log entries kept for pages that connect later
FRAMES_KEEP = 60  # decoded frames kept per tap
TAP_RETRY_S = 2.0

TapSpec = str | tuple[str, int]
# Type II opcodes whose items are code numbers (protocols/type2.yaml)
IDENT_OP, INDICATION_OP, CONTROL_OP, CONTROL_RESULT_OP = 0x01, 0x10, 0x20, 0x21


def load_charts(
    stations: Iterable[int], folder: str | Path | None = None
) -> dict[int, tuple[CodeChart, CodeChart]]:
    """`{n: (ixl_to_ctc, ctc_to_ixl)}` from `code_charts/stNN_*.yaml` (default: the shipped ones)."""
    base = Path(folder) if folder is not None else data_dir("code_charts")
    return {
        n: (
            load_chart(base / f"st{n}_ixl_to_ctc.yaml"),
            load_chart(base / f"st{n}_ctc_to_ixl.yaml"),
        )
        for n in stations
    }


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int((t % 1) * 1000):03d}"


@dataclass(eq=False)
class _Client:
    ws: web.WebSocketResponse
    tap: int | None = None
    train: str | None = None
    train_task: asyncio.Task[None] | None = None


@dataclass
class _TapFeed:
    """One tap's traffic, decoded and rendered in the Fig. 7 console style."""

    spec: TapSpec
    label: str
    entries: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=FRAMES_KEEP))
    status: str = "not connected"
    station: int | None = None  # Type II: learnt from the IDENT frame, to name codes
    task: asyncio.Task[None] | None = None


class ConsoleServer:
    """The operator console of one CTC. See the module docstring."""

    def __init__(
        self,
        ctc_server: CtcServer,
        tables: IndicationTables,
        stations: Line,
        charts: Mapping[int, tuple[CodeChart, CodeChart]] | None = None,
        taps: Sequence[TapSpec] = (),
        trains: TrainSource | Mapping[str, TrainEndpoint] | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
    ) -> None:
        self.ctc = ctc_server
        self.tables = tables
        self.line = stations
        numbers = [n for n in tables.stations if n in stations.stations]
        self.models: dict[int, StationModel] = station_models(
            stations, charts if charts is not None else load_charts(numbers)
        )
        self.layout = build(stations)
        self.taps = [_TapFeed(t, t if isinstance(t, str) else f"{t[0]}:{t[1]}") for t in taps]
        if trains is None or isinstance(trains, Mapping):
            self.trains: TrainSource | None = EndpointTrains(trains) if trains else None
        else:
            self.trains = trains
        self.host = host
        self._port = port
        self.log_entries: deque[dict[str, Any]] = deque(maxlen=LOG_KEEP)
        self._clients: set[_Client] = set()
        self._runner: web.AppRunner | None = None
        self._site: web.TCPSite | None = None
        self._last_state = ""
        self._flush_scheduled = False
        self._poller: asyncio.Task[None] | None = None
        self._chained: Any = None
        self._hook: Any = None

    # ------------------------------------------------------------------ life cycle

    async def start(self) -> None:
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/diagram.svg", self._diagram)
        app.router.add_get("/api/state", self._api_state)
        app.router.add_get("/ws", self._websocket)
        app.router.add_static("/static/", STATIC)
        self._runner = web.AppRunner(app, access_log=None)
        await self._runner.setup()
        self._site = web.TCPSite(self._runner, self.host, self._port)
        await self._site.start()
        self._chained = self.ctc.on_event

        def hook(station: int | None, event: ev.Event) -> None:
            if self._chained is not None:
                self._chained(station, event)
            self._changed()

        self._hook = hook
        self.ctc.on_event = hook
        self._poller = asyncio.get_running_loop().create_task(self._poll())
        log.info("CTC console at %s", self.url)

    @property
    def port(self) -> int:
        if self._runner is None or not self._runner.addresses:
            raise UsageError("the console is not started")
        return int(self._runner.addresses[0][1])

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    async def close(self) -> None:
        if self.ctc.on_event is self._hook:
            self.ctc.on_event = self._chained
        tasks = [t for t in (self._poller, *(f.task for f in self.taps)) if t is not None]
        tasks += [c.train_task for c in self._clients if c.train_task is not None]
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for c in list(self._clients):
            await c.ws.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    async def __aenter__(self) -> ConsoleServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # ------------------------------------------------------------------ state

    def snapshot(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for n, model in self.models.items():
            view = self.tables.stations.get(n)
            if view is None:
                out[str(n)] = model.picture({}, False, False)
            else:
                out[str(n)] = model.picture(view.state, view.connected, view.synced)
        return out

    def _changed(self) -> None:
        if not self._flush_scheduled:
            self._flush_scheduled = True
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        text = json.dumps({"type": "state", "stations": self.snapshot()})
        if text != self._last_state:
            self._last_state = text
            self._broadcast_text(text)

    async def _poll(self) -> None:
        while True:
            await asyncio.sleep(POLL_S)
            self._flush()

    def _broadcast_text(self, text: str, clients: Iterable[_Client] | None = None) -> None:
        for c in list(self._clients if clients is None else clients):
            if not c.ws.closed:
                asyncio.get_running_loop().create_task(self._send(c, text))

    async def _send(self, c: _Client, text: str) -> None:
        with contextlib.suppress(ConnectionError, RuntimeError):
            await c.ws.send_str(text)

    def _log(self, text: str, level: str = "info") -> dict[str, Any]:
        now = time.time()
        entry = {"time": _clock(now), "t": now, "text": text, "level": level}
        self.log_entries.append(entry)
        pylevel = logging.WARNING if level == "error" else logging.INFO
        log.log(pylevel, "%s", text)
        self._broadcast_text(json.dumps({"type": "log", "entry": entry}))
        return entry

    # ------------------------------------------------------------------ operator actions

    def _model(self, msg: Mapping[str, Any]) -> StationModel:
        try:
            return self.models[int(msg["station"])]
        except (KeyError, ValueError, TypeError):
            raise UsageError(f"unknown station {msg.get('station')!r}") from None

    def _action_of(self, msg: Mapping[str, Any]) -> Action:
        kind = msg.get("type")
        model = self._model(msg)
        if kind == "route_set":
            return model.set_route(str(msg["entry"]), str(msg["exit"]))
        if kind == "route_cancel":
            view = self.tables.stations.get(model.number)
            return model.cancel_route(str(msg["entry"]), view.state if view else {})
        if kind == "point":
            return model.move_point(str(msg["point"]), str(msg["position"]))
        if kind == "mode":
            return model.mode(str(msg["mode"]))
        raise UsageError(f"unknown request {kind!r}")

    async def perform(self, msg: Mapping[str, Any]) -> dict[str, Any]:
        """Carry out one operator request; the result as sent to the page (and logged)."""
        try:
            action = self._action_of(msg)
        except (UsageError, KeyError) as exc:
            text = str(exc).strip("'\"")
            self._log(f"refused by the console: {text}", "error")
            return {"ok": False, "reason": text, "text": text}
        self._log(f"{action.text} ({action.name}={action.value}) sent")
        try:
            result = await self.ctc.control(
                action.station, action.code, action.value, CONTROL_TIMEOUT_S
            )
        except UsageError as exc:
            reason = str(exc)
        except TimeoutError:
            reason = f"no CONTROL_RESULT within {CONTROL_TIMEOUT_S:g} s"
        except PeerError as exc:
            reason = str(exc)
        else:
            if result.accepted:
                text = f"{action.text}: accepted"
                self._log(text, "ok")
                return {"ok": True, "reason": None, "text": text}
            reason = result.reason_name or f"reason {result.reason}"
        text = f"{action.text}: rejected: {reason}"
        self._log(text, "error")
        return {"ok": False, "reason": reason, "text": text}

    # ------------------------------------------------------------------ HTTP

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _diagram(self, request: web.Request) -> web.Response:
        return web.Response(text=self.layout.svg, content_type="image/svg+xml")

    async def _api_state(self, request: web.Request) -> web.Response:
        trains = self.trains.train_ids() if self.trains is not None else []
        return web.json_response(
            {"stations": self.snapshot(), "trains": trains, "log": list(self.log_entries)}
        )

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=20.0)
        await ws.prepare(request)
        client = _Client(ws)
        self._clients.add(client)
        hello = {
            "type": "hello",
            "line": self.line.name,
            "stations": sorted(self.models),
            "taps": [t.label for t in self.taps],
            "trains": self.trains.train_ids() if self.trains is not None else [],
            "log": list(self.log_entries),
        }
        await ws.send_str(json.dumps(hello))
        await ws.send_str(json.dumps({"type": "state", "stations": self.snapshot()}))
        try:
            async for raw in ws:
                if raw.type != WSMsgType.TEXT:
                    continue
                try:
                    msg = json.loads(raw.data)
                except ValueError:
                    continue
                if isinstance(msg, dict):
                    await self._on_message(client, msg)
        finally:
            self._clients.discard(client)
            if client.train_task is not None:
                client.train_task.cancel()
        return ws

    async def _on_message(self, client: _Client, msg: dict[str, Any]) -> None:
        kind = msg.get("type")
        if kind in ("route_set", "route_cancel", "point", "mode"):

            async def run() -> None:
                result = await self.perform(msg)
                result.update(type="result", id=msg.get("id"))
                await self._send(client, json.dumps(result))

            asyncio.get_running_loop().create_task(run())
        elif kind == "monitor":
            self._select_tap(client, msg.get("tap"))
        elif kind == "train":
            self._select_train(client, msg.get("train"))

    # ------------------------------------------------------------------ link monitor

    def _select_tap(self, client: _Client, index: object) -> None:
        if not isinstance(index, int) or not 0 <= index < len(self.taps):
            client.tap = None
            return
        client.tap = index
        feed = self.taps[index]
        if feed.task is None:
            feed.task = asyncio.get_running_loop().create_task(self._follow(index))
        payload = {"type": "frames", "tap": index, "reset": True, "status": feed.status,
                   "entries": list(feed.entries)}  # fmt: skip
        asyncio.get_running_loop().create_task(self._send(client, json.dumps(payload)))

    def _tap_push(self, index: int, entries: list[dict[str, Any]], reset: bool = False) -> None:
        feed = self.taps[index]
        payload = {"type": "frames", "tap": index, "reset": reset, "status": feed.status,
                   "entries": entries}  # fmt: skip
        self._broadcast_text(json.dumps(payload), [c for c in self._clients if c.tap == index])

    async def _follow(self, index: int) -> None:
        """Subscribe to the tap's control port; decode and keep its frames; retry when it goes."""
        feed = self.taps[index]
        while True:
            writer: asyncio.StreamWriter | None = None
            try:
                host, port = resolve_tap(feed.spec) if isinstance(feed.spec, str) else feed.spec
                reader, writer = await asyncio.open_connection(host, port)
                writer.write(b"subscribe history\n")
                await writer.drain()
                header_line = (await reader.readline()).decode("utf-8", "replace").strip()
                if not header_line.startswith("ok "):
                    raise PeerError(f"tap answered {header_line!r}")
                header = json.loads(header_line[3:])
                profile = get_profile(str(header.get("profile", "ktcs-type1")))
                names = header.get("names")
                feed.status = f"tap {header.get('tap') or feed.label}: {profile.name}" + (
                    f", ends {names[0]} / {names[1]}" if isinstance(names, list) else ""
                )
                self._tap_push(index, [])
                while True:
                    line = await reader.readline()
                    if not line:
                        raise PeerError("the tap closed its control port")
                    item = json.loads(line)
                    if "hex" in item:
                        entries = self._render(feed, item, profile)
                    else:
                        detail = " ".join(
                            f"{k}={v}" for k, v in item.items() if k not in ("time", "event")
                        )
                        t = float(item.get("time") or time.time())
                        entries = [{"time": _clock(t), "direction": "", "ok": True,
                                    "text": f"-- {item.get('event')}: {detail}"}]  # fmt: skip
                    feed.entries.extend(entries)
                    self._tap_push(index, entries)
            except asyncio.CancelledError:
                raise
            except (OSError, ValueError, KtcsError) as exc:
                feed.status = f"tap {feed.label}: {exc}"
                self._tap_push(index, [])
            finally:
                if writer is not None:
                    writer.close()
            await asyncio.sleep(TAP_RETRY_S)

    def _chart_for(self, feed: _TapFeed, frame: Frame, profile: FrameProfile) -> CodeChart | None:
        """Type II: the station's chart for the codes this frame carries (by opcode)."""
        if profile.protocol != "type2" or frame.op is None or frame.error is not None:
            return None
        if frame.op == IDENT_OP and len(frame.data) >= 2:
            feed.station = int.from_bytes(frame.data[:2], "little")
        model = self.models.get(feed.station) if feed.station is not None else None
        if model is None:
            return None
        if frame.op in (INDICATION_OP, CONTROL_RESULT_OP):
            return model.indications
        if frame.op == CONTROL_OP:
            return model.controls
        return None

    def _render(
        self, feed: _TapFeed, item: Mapping[str, Any], profile: FrameProfile
    ) -> list[dict[str, Any]]:
        data = bytes.fromhex(str(item["hex"]))
        t = float(item.get("time") or time.time())
        direction = str(item.get("direction", ""))
        dec = StreamDecoder(profile)
        out = []
        for rec in dec.feed(data) + dec.close():
            ok = isinstance(rec, Frame) and rec.error is None
            chart = self._chart_for(feed, rec, profile) if isinstance(rec, Frame) else None
            label = f"{_clock(t)} {direction}  "
            out.append({"time": _clock(t), "direction": direction, "ok": ok,
                        "text": to_text(rec, profile, chart, label=label)})  # fmt: skip
        return out

    # ------------------------------------------------------------------ speed–distance

    def _select_train(self, client: _Client, train: object) -> None:
        if client.train_task is not None:
            client.train_task.cancel()
            client.train_task = None
        client.train = train if isinstance(train, str) else None
        if client.train is not None and self.trains is not None:
            client.train_task = asyncio.get_running_loop().create_task(
                self._watch_train(client, client.train)
            )

    async def _watch_train(self, client: _Client, train: str) -> None:
        assert self.trains is not None
        last = ""
        while not client.ws.closed:
            try:
                data = await self.trains.speed_distance(train)
            except Exception:  # a provider failing must not take the console down
                log.exception("speed-distance provider failed for train %s", train)
                data = None
            text = json.dumps(
                {"type": "speed", "train": train, "data": data.to_json() if data else None}
            )
            if text != last:
                last = text
                await self._send(client, text)
            await asyncio.sleep(TRAIN_PERIOD_S)
