"""The CTC operator console (seed 004 Fig. 8) as a web page served by the CTC process (aiohttp).

`ConsoleServer` serves the track diagram and a websocket that pushes the station pictures the
CTC's model draws (`ctc.model.CtcModel.picture`) whenever the CTC's state changes, and hands the
operator's clicks to the CTC's desk (`ctc.desk.Desk.operate`, the same path `ktcs-bench ctc`
takes), whose results come back to the page and the log. Side panels: a link monitor over tap
control ports (Fig. 7 console text) and a speed–distance view of a train (`trains.TrainSource`);
the trains stand on the diagram where their source says, each labelled with its number at its
front (a `trains` message to the pages every `TRAIN_PERIOD_S`, placed by `diagram.Layout.place`).
Given the CTC's automatic route setting (`ars`, an `ArsSwitch`), each station card shows whether
ARS is on there and switches it (a click goes the same way as the operator's other requests), and
the CTC hands ARS's log to `note_ars`: what ARS asked for, what came of it and why a train waits go
to the page's Log panel beside the operator's requests.

The console never starves the lab it serves (it may share its loop with every device): each page's
requests pass the `gate.Gate` -- a rate per page and per console, a short queue per page worked one
request at a time, a bound on the controls outstanding per station -- and one beyond a bound is
answered `busy` at once, not sent; the websocket's reader takes one message per turn of the loop,
so the lab's timers and links come first; a page that reads nothing is dropped before its backlog
grows without end, and the console takes at most `MAX_PAGES` pages.

Embedding (e.g. in the CTC emulator process, on its event loop):

    console = ConsoleServer(desk, taps=["st18-ctc"])
    await console.start(); print(console.url); ...; await console.close()

It chains itself onto the server's `on_event` (restored on close) and also re-checks the state
every `POLL_S`, so it needs nothing else from the CTC.

Who may operate through it: a websocket is accepted only from the console's own pages -- its
Origin is the console's own address (127.0.0.1, localhost or [::1] at its port, the address it
is bound to, or the IP literal a page reached it by when bound to all interfaces) or one of
`origins` (the lab file's `console: origins:`) -- so no other web page in the operator's browser
can set a route. A DNS name is never taken on the page's word (DNS rebinding). The tap feeds
present the lab's token (`token`, else the one `runtime.client_token` finds).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import logging
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypedDict
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from ktcs_bench import kinds
from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.codec.render import to_text
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.console.diagram import build
from ktcs_bench.console.gate import Gate, Page
from ktcs_bench.console.trains import EndpointTrains, TrainPosition, TrainSource
from ktcs_bench.ctc.desk import Desk
from ktcs_bench.ctc.log import command_words
from ktcs_bench.ctc.model import Action, StationPicture
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.runtime import client_token
from ktcs_bench.station_codes.chart import CodeChart
from ktcs_bench.tap.registry import resolve_tap
from ktcs_bench.train.endpoint import TrainEndpoint
from ktcs_bench.transport import jsonlines
from ktcs_bench.type2 import events as ev

log = logging.getLogger("ktcs_bench.console")

STATIC = Path(__file__).resolve().parent / "static"
POLL_S = 0.5  # state re-check besides the CTC's events (link state, missed callbacks)
TRAIN_PERIOD_S = 0.5  # speed–distance refresh for a client watching a train, and the trains' places
LOG_KEEP = 300  # log entries kept for pages that connect later
FRAMES_KEEP = 60  # decoded frames kept per tap
TAP_RETRY_S = 2.0
MAX_PAGES = 64  # websockets at once; more are refused (503)
MAX_MESSAGE = 64 * 1024  # bytes of one message from a page (a request is some 100)
BACKLOG = 1000  # messages to one page not yet written; beyond, the page is dropped as too slow

TapSpec = str | tuple[str, int]
# Type II opcodes whose items are code numbers (protocols/type2.yaml)
IDENT_OP, INDICATION_OP, CONTROL_OP, CONTROL_RESULT_OP = 0x01, 0x10, 0x20, 0x21
# the page's requests -> the CTC control port's command words (`CtcModel.action`)
REQUESTS = {
    "route_set": {"cmd": "route", "action": "set"},
    "route_cancel": {"cmd": "route", "action": "cancel"},  # the route set from the clicked entry
    "point": {"cmd": "point"},
    "mode": {"cmd": "mode"},
    "direction": {"cmd": "direction"},  # the station asks for an interval's permission (§6.6)
}
REQUEST_FIELDS = ("station", "entry", "exit", "point", "position", "mode", "interval")


class ArsSwitch(Protocol):
    """The CTC's automatic route setting as the console sees it (the CTC device is one)."""

    def ars_state(self) -> dict[str, bool] | None:
        """Station (as text) -> ARS on; None: the CTC runs no timetable."""
        ...

    def switch_ars(self, station: object, on: bool) -> list[int]:
        """ARS on or off at `station`; the stations switched. UsageError if it cannot."""
        ...


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int((t % 1) * 1000):03d}"


class FrameEntry(TypedDict):
    """One line of a tap's panel: a frame (or a tap event) as the page shows it."""

    time: str
    direction: str
    ok: bool
    text: str


class LogPanelEntry(TypedDict):
    """One entry of the page's Log panel."""

    time: str
    t: float
    text: str
    level: str
    source: str


class RequestResult(TypedDict):
    """What came of a page's request: done (ok), or the reason it was not; in words."""

    ok: bool
    reason: str | None
    text: str


class ResultAnswer(RequestResult):
    """`RequestResult` as sent to the page, with the request's id."""

    type: str
    id: object


@dataclass(eq=False)
class _Client:
    ws: web.WebSocketResponse
    page: Page
    peer: str = "?"
    transport: asyncio.Transport | None = None
    tap: int | None = None
    train: str | None = None
    train_task: asyncio.Task[None] | None = None
    # the page's admitted requests, carried out one at a time by `worker`
    queue: asyncio.Queue[dict[str, Any]] = field(default_factory=asyncio.Queue)
    worker: asyncio.Task[None] | None = None
    backlog: int = 0  # messages being written to it
    dropped: bool = False


@dataclass
class _TapFeed:
    """One tap's traffic, decoded and rendered in the Fig. 7 console style."""

    spec: TapSpec
    label: str
    entries: deque[FrameEntry] = field(default_factory=lambda: deque(maxlen=FRAMES_KEEP))
    status: str = "not connected"
    station: int | None = None  # Type II: learnt from the IDENT frame, to name codes
    task: asyncio.Task[None] | None = None


class ConsoleServer:
    """The operator console of one CTC. See the module docstring."""

    def __init__(
        self,
        desk: Desk,
        taps: Sequence[TapSpec] = (),
        trains: TrainSource | Mapping[str, TrainEndpoint] | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        origins: Sequence[str] = (),
        token: str | None = None,
        ars: ArsSwitch | None = None,
        gate: Gate | None = None,
    ) -> None:
        self.desk = desk
        self.ars = ars
        self.ctc = desk.server
        self.model = desk.model
        self.line = desk.model.line
        self.layout = build(self.line)
        self.taps = [_TapFeed(t, t if isinstance(t, str) else f"{t[0]}:{t[1]}") for t in taps]
        if trains is None or isinstance(trains, Mapping):
            self.trains: TrainSource | None = EndpointTrains(trains) if trains else None
        else:
            self.trains = trains
        self.host = host
        self._port = port
        self.origins = frozenset(o.rstrip("/").lower() for o in origins)
        self.token = token
        self.log_entries: deque[LogPanelEntry] = deque(maxlen=LOG_KEEP)
        self.gate = gate or Gate()
        self.busy_answers = 0  # requests answered busy, over all pages
        self._clients: set[_Client] = set()
        self._runner: web.AppRunner | None = None
        self._site: web.TCPSite | None = None
        self._last_state = ""
        self._flush_scheduled = False
        self._poller: asyncio.Task[None] | None = None
        self._train_poller: asyncio.Task[None] | None = None
        self._last_trains = ""
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

        def hook(station: int | None, event: ev.SessionEvent) -> None:
            if self._chained is not None:
                self._chained(station, event)
            self._changed()

        self._hook = hook
        self.ctc.on_event = hook
        self._poller = asyncio.get_running_loop().create_task(self._poll())
        if self.trains is not None:
            self._train_poller = asyncio.get_running_loop().create_task(self._poll_trains())
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
        pollers = (self._poller, self._train_poller)
        tasks = [t for t in (*pollers, *(f.task for f in self.taps)) if t is not None]
        tasks += [c.train_task for c in self._clients if c.train_task is not None]
        tasks += [c.worker for c in self._clients if c.worker is not None]
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

    def snapshot(self) -> dict[str, StationPicture]:
        return {str(n): self.model.picture(n) for n in self.model.models}

    def ars_state(self) -> dict[str, bool] | None:
        return self.ars.ars_state() if self.ars is not None else None

    def _state_text(self) -> str:
        return json.dumps({"type": "state", "stations": self.snapshot(), "ars": self.ars_state()})

    def _changed(self) -> None:
        if not self._flush_scheduled:
            self._flush_scheduled = True
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        text = self._state_text()
        if text != self._last_state:
            self._last_state = text
            self._broadcast_text(text)

    async def _poll(self) -> None:
        while True:
            await asyncio.sleep(POLL_S)
            self._flush()
            for c in list(self._clients):
                self._report_busy(c)

    def _broadcast_text(self, text: str, clients: Iterable[_Client] | None = None) -> None:
        for c in list(self._clients if clients is None else clients):
            if not c.ws.closed:
                asyncio.get_running_loop().create_task(self._send(c, text))

    async def _send(self, c: _Client, text: str) -> None:
        if c.backlog >= BACKLOG:  # it reads nothing: drop it rather than hold all it is owed
            if not c.dropped:
                c.dropped = True
                log.warning("console: dropped the page at %s: %d messages unread", c.peer,
                            c.backlog)  # fmt: skip
                if c.transport is not None:
                    c.transport.abort()
            return
        c.backlog += 1
        try:
            with contextlib.suppress(ConnectionError, RuntimeError):
                await c.ws.send_str(text)
        finally:
            c.backlog -= 1

    def _log(
        self, text: str, level: str = "info", source: str = "console", echo: bool = True
    ) -> LogPanelEntry:
        """An entry in the page's Log panel (`source`: console, ars); `echo`: to Python logging
        too (ARS's entries are there already, as the CTC device's events)."""
        now = time.time()
        entry: LogPanelEntry = {
            "time": _clock(now),
            "t": now,
            "text": text,
            "level": level,
            "source": source,
        }
        self.log_entries.append(entry)
        if echo:
            pylevel = logging.WARNING if level in ("error", "busy") else logging.INFO
            log.log(pylevel, "%s", text)
        self._broadcast_text(json.dumps({"type": "log", "entry": entry}))
        return entry

    def note_ars(self, entry: Mapping[str, Any]) -> None:
        """One entry of ARS's log (`ctc.ars.Ars.on_log`: what it asked for, what came of it, why
        a train waits), to the Log panel."""
        self._log(f"ARS: {entry.get('text')}", "ars", source="ars", echo=False)

    # ------------------------------------------------------------------ operator actions

    async def perform(self, msg: Mapping[str, Any]) -> RequestResult:
        """Carry out one operator request; the result as sent to the page (and logged)."""
        kind = msg.get("type")
        if kind == "ars":
            return self._switch_ars(msg)
        words = REQUESTS.get(kind) if isinstance(kind, str) else None
        if words is None:
            text = f"unknown request {kind!r}"
            self._log(f"refused by the console: {text}", "error")
            return {"ok": False, "reason": text, "text": text}
        command = {**words, **{k: msg[k] for k in REQUEST_FIELDS if k in msg}}

        def sent(action: Action) -> None:
            self._log(f"{action.text} ({action.name}={action.value}) sent")

        outcome = await self.desk.operate(command, "console", on_sent=sent)
        if outcome.action is None:
            text = str(outcome.why)
            self._log(f"refused by the CTC: {text}", "error")
            return {"ok": False, "reason": text, "text": text}
        if outcome.accepted:
            text = f"{outcome.action.text}: accepted"
            self._log(text, "ok")
            return {"ok": True, "reason": None, "text": text}
        text = f"{outcome.action.text}: rejected: {outcome.why}"
        self._log(text, "error")
        return {"ok": False, "reason": outcome.why, "text": text}

    def _switch_ars(self, msg: Mapping[str, Any]) -> RequestResult:
        station, on = msg.get("station"), msg.get("on")
        what = f"station {station}: ARS {'on' if on else 'off'}"
        try:
            if self.ars is None:
                raise UsageError("this CTC runs no timetable (no ars: in its lab file)")
            if not isinstance(on, bool) or station is None:
                raise UsageError("an ARS switch needs a station and on: true or false")
            self.ars.switch_ars(station, on)
        except UsageError as exc:
            self._log(f"refused by the CTC: {what}: {exc}", "error")
            return {"ok": False, "reason": str(exc), "text": f"{what}: {exc}"}
        self._log(what, "ok")
        self._changed()
        return {"ok": True, "reason": None, "text": what}

    # ------------------------------------------------------------------ HTTP

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _diagram(self, request: web.Request) -> web.Response:
        return web.Response(text=self.layout.svg, content_type="image/svg+xml")

    async def _api_state(self, request: web.Request) -> web.Response:
        trains = self.trains.train_ids() if self.trains is not None else []
        return web.json_response(
            {
                "stations": self.snapshot(),
                "ars": self.ars_state(),
                "trains": trains,
                "log": list(self.log_entries),
            }  # fmt: skip
        )

    def origin_allowed(self, origin: str, host_header: str | None) -> bool:
        """Whether a page from `origin` may operate (see the module docstring)."""
        origin = origin.rstrip("/").lower()
        if origin in self.origins:
            return True
        port = self.port
        hosts = {"127.0.0.1", "localhost", "[::1]"}
        wildcard = self.host in ("", "0.0.0.0", "::")
        if not wildcard:
            hosts.add(f"[{self.host}]" if ":" in self.host else self.host.lower())
        elif host_header:  # reached by an address of this machine: only an IP literal counts
            with contextlib.suppress(ValueError):
                url = urlsplit(f"http://{host_header}")
                if url.hostname and url.port == port:
                    ipaddress.ip_address(url.hostname)
                    hosts.add(url.netloc.lower().rsplit(":", 1)[0])
        own = {f"http://{h}:{port}" for h in hosts}
        if port == 80:
            own |= {f"http://{h}" for h in hosts}
        return origin in own

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and not self.origin_allowed(origin, request.headers.get("Host")):
            log.warning("console: refused a websocket from %s (Origin %s)", request.remote, origin)
            return web.Response(
                status=403,
                text=f"refused: this console takes operators from its own pages only, not from "
                f"{origin} (a lab file may allow more under console: origins:)\n",
            )
        if len(self._clients) >= MAX_PAGES:
            return web.Response(
                status=503, text=f"console busy: {len(self._clients)} pages are connected\n"
            )
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=MAX_MESSAGE)
        await ws.prepare(request)
        client = _Client(ws, self.gate.page(), str(request.remote), request.transport)
        self._clients.add(client)
        client.worker = asyncio.get_running_loop().create_task(self._work(client))
        hello = {
            "type": "hello",
            "line": self.line.name,
            "stations": sorted(self.model.models),
            "taps": [t.label for t in self.taps],
            "trains": self.trains.train_ids() if self.trains is not None else [],
            "log": list(self.log_entries),
        }
        await ws.send_str(json.dumps(hello))
        await ws.send_str(self._state_text())
        if self._last_trains:
            await ws.send_str(self._last_trains)
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
                # one message a turn of the loop: the lab's timers and links go first
                await asyncio.sleep(0)
        finally:
            self._clients.discard(client)
            for task in (client.train_task, client.worker):
                if task is not None:
                    task.cancel()
            self._report_busy(client, final=True)
        return ws

    async def _on_message(self, client: _Client, msg: dict[str, Any]) -> None:
        kind = msg.get("type")
        if isinstance(kind, str) and (kind in REQUESTS or kind == "ars"):
            why = self.gate.admit(client.page, time.monotonic(), client.queue.qsize())
            if why is None:
                client.queue.put_nowait(msg)
            else:
                await self._busy(client, msg, why)
        elif kind == "monitor":
            await self._select_tap(client, msg.get("tap"))
        elif kind == kinds.TRAIN:
            self._select_train(client, msg.get(kinds.TRAIN))

    async def _work(self, client: _Client) -> None:
        """The page's admitted requests, one at a time, each answered with its result."""
        while True:
            msg = await client.queue.get()
            why = self._station_busy(client, msg)
            if why is not None:
                await self._busy(client, msg, why)
                continue
            try:
                result = await self.perform(msg)
            except Exception:  # a request failing must not stop the page's others
                log.exception("console: request %r failed", msg)
                result = {"ok": False, "reason": "internal error", "text": "internal error"}
            answer: ResultAnswer = {**result, "type": "result", "id": msg.get("id")}
            await self._send(client, json.dumps(answer))

    def _station_busy(self, client: _Client, msg: Mapping[str, Any]) -> str | None:
        """Why `msg` may not go out now (its station's controls outstanding), or None."""
        if msg.get("type") not in REQUESTS:
            return None
        try:
            station = self.model.station(msg.get("station")).number
        except UsageError:
            return None  # `perform` refuses it, sending nothing
        return self.gate.dispatch(client.page, station, self.desk.outstanding.get(station, 0))

    async def _busy(self, client: _Client, msg: Mapping[str, Any], why: str) -> None:
        """Answer `msg` busy: not sent, because of `why` (a `Gate` bound)."""
        self.busy_answers += 1
        kind = msg.get("type")
        words = REQUESTS.get(kind) if isinstance(kind, str) else None
        if words is not None:
            what = command_words({**words, **{k: msg[k] for k in REQUEST_FIELDS if k in msg}})
        else:
            what = f"ARS {'on' if msg.get('on') else 'off'} at station {msg.get('station')}"
        text = f"console busy: {what} not sent ({why}); try again"
        answer = {"type": "busy", "id": msg.get("id"), "request": kind, "reason": why, "text": text}
        self._report_busy(client)
        await self._send(client, json.dumps(answer))

    def _report_busy(self, client: _Client, final: bool = False) -> None:
        """The page's busy answers to the log, when `Gate.report` says they are due."""
        count = self.gate.report(client.page, time.monotonic(), final)
        if count:
            many = "request" if count == 1 else "requests"
            self._log(f"console busy: {count} {many} from the page at {client.peer} answered "
                      f"busy, not sent ({client.page.why})", "busy")  # fmt: skip

    # ------------------------------------------------------------------ link monitor

    async def _select_tap(self, client: _Client, index: object) -> None:
        if not isinstance(index, int) or not 0 <= index < len(self.taps):
            client.tap = None
            return
        client.tap = index
        feed = self.taps[index]
        if feed.task is None:
            feed.task = asyncio.get_running_loop().create_task(self._follow(index))
        payload = {"type": "frames", "tap": index, "reset": True, "status": feed.status,
                   "entries": list(feed.entries)}  # fmt: skip
        await self._send(client, json.dumps(payload))

    def _tap_push(self, index: int, entries: list[FrameEntry], reset: bool = False) -> None:
        feed = self.taps[index]
        payload = {"type": "frames", "tap": index, "reset": reset, "status": feed.status,
                   "entries": entries}  # fmt: skip
        self._broadcast_text(json.dumps(payload), [c for c in self._clients if c.tap == index])

    async def _follow(self, index: int) -> None:
        """Subscribe to the tap's control port; decode and keep its frames; retry when it goes."""
        feed = self.taps[index]
        while True:
            peer: jsonlines.Peer | None = None
            try:
                host, port = resolve_tap(feed.spec) if isinstance(feed.spec, str) else feed.spec
                token = self.token or client_token((host, port)) or ""
                peer = await jsonlines.connect(host, port)
                peer.send({"cmd": "subscribe", "history": True, "token": token})
                header = await peer.read()
                if not (header and header.get("ok") is True):
                    raise PeerError(f"tap answered {header!r}")
                profile = get_profile(str(header.get("profile", "ktcs-type1")))
                names = header.get("names")
                feed.status = f"tap {header.get('tap') or feed.label}: {profile.name}" + (
                    f", ends {names[0]} / {names[1]}" if isinstance(names, list) else ""
                )
                self._tap_push(index, [])
                while True:
                    item = await peer.read()
                    if item is None:
                        raise PeerError("the tap closed its control port")
                    if "hex" in item:
                        entries = self._render(feed, item, profile)
                    else:
                        detail = " ".join(
                            f"{k}={v}" for k, v in item.items() if k not in ("time", "event")
                        )
                        stamp = item.get("time")
                        t = (
                            float(stamp)
                            if isinstance(stamp, (int, float)) and stamp
                            else time.time()
                        )
                        entries = [FrameEntry(time=_clock(t), direction="", ok=True,
                                              text=f"-- {item.get('event')}: {detail}")]  # fmt: skip
                    feed.entries.extend(entries)
                    self._tap_push(index, entries)
            except asyncio.CancelledError:
                raise
            except (OSError, ValueError, KtcsError) as exc:
                feed.status = f"tap {feed.label}: {exc}"
                self._tap_push(index, [])
            finally:
                if peer is not None:
                    peer.close()
            await asyncio.sleep(TAP_RETRY_S)

    def _chart_for(self, feed: _TapFeed, frame: Frame, profile: FrameProfile) -> CodeChart | None:
        """Type II: the station's chart for the codes this frame carries (by opcode)."""
        if profile.protocol != "type2" or frame.op is None or frame.error is not None:
            return None
        if frame.op == IDENT_OP and len(frame.data) >= 2:
            feed.station = int.from_bytes(frame.data[:2], "little")
        model = self.model.models.get(feed.station) if feed.station is not None else None
        if model is None:
            return None
        if frame.op in (INDICATION_OP, CONTROL_RESULT_OP):
            return model.indications
        if frame.op == CONTROL_OP:
            return model.controls
        return None

    def _render(
        self, feed: _TapFeed, item: Mapping[str, Any], profile: FrameProfile
    ) -> list[FrameEntry]:
        data = bytes.fromhex(str(item["hex"]))
        t = float(item.get("time") or time.time())
        direction = str(item.get("direction", ""))
        dec = StreamDecoder(profile)
        out: list[FrameEntry] = []
        for rec in dec.feed(data) + dec.close():
            ok = isinstance(rec, Frame) and rec.error is None
            chart = self._chart_for(feed, rec, profile) if isinstance(rec, Frame) else None
            label = f"{_clock(t)} {direction}  "
            out.append({"time": _clock(t), "direction": direction, "ok": ok,
                        "text": to_text(rec, profile, chart, label=label)})  # fmt: skip
        return out

    # ------------------------------------------------------------------ trains on the diagram

    def _trains_text(self, positions: Iterable[TrainPosition]) -> str:
        trains = [
            {**p.to_json(), **self.layout.place(p.head_m, p.tail_m, p.track).to_json()}
            for p in positions
        ]
        return json.dumps({"type": "trains", "trains": trains})

    async def _poll_trains(self) -> None:
        """Every TRAIN_PERIOD_S while a page watches: where each train stands, to every page
        (when it changed)."""
        assert self.trains is not None
        while True:
            if self._clients:
                try:
                    text = self._trains_text(await self.trains.positions())
                except Exception:  # a provider failing must not take the console down
                    log.exception("train positions provider failed")
                else:
                    if text != self._last_trains:
                        self._last_trains = text
                        self._broadcast_text(text)
            await asyncio.sleep(TRAIN_PERIOD_S)

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
                {"type": "speed", kinds.TRAIN: train, "data": data.to_json() if data else None}
            )
            if text != last:
                last = text
                await self._send(client, text)
            await asyncio.sleep(TRAIN_PERIOD_S)
