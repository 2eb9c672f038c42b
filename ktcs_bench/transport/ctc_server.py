"""The CTC's Type II server: accept, TLS handshake, admission, one link per station.

`CtcServer` admits IXLs (who may connect is decided by `admission.AdmissionPolicy`), runs one
`CtcConnection` per accepted stream through a `SessionPump`, sends controls and matches their
results. What the CTC knows of each station is not kept here: the server tells its
`CtcApplication` (the CTC's model) when a station's link comes up or goes down and what it
indicates.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl as ssl_module
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.transport import net
from ktcs_bench.transport.type2_pump import EventCallback, SessionPump, Waitable
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.admission import AdmissionPolicy, BadFrameMeter
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ctc_side import CtcConnection

log = logging.getLogger("ktcs_bench.type2")

DEFAULT_HOST = "127.0.0.1"  # SPEC §10: binding anywhere else is an explicit choice


class CtcApplication(Protocol):
    """What the CTC server tells the CTC about each station (the CTC's model implements it)."""

    def link_up(self, station: int, peer: str) -> None:
        """The station's IXL identified itself and was admitted (its full state comes next)."""
        ...

    def link_down(self, station: int) -> None:
        """The station's link is gone; nothing it indicated can be trusted until it is back."""
        ...

    def full_state(self, station: int, items: Sequence[ev.Item]) -> None:
        """Every indication code's state, in chart order: it replaces what was known."""
        ...

    def indications(self, station: int, items: Sequence[ev.Item]) -> None:
        """Change indications, in the order they were sent."""
        ...


def _peer_name(writer: asyncio.StreamWriter) -> tuple[str, str]:
    peer = writer.get_extra_info("peername")
    if isinstance(peer, tuple) and len(peer) >= 2:
        host = str(peer[0])
        return host, f"[{host}]:{peer[1]}" if ":" in host else f"{host}:{peer[1]}"
    return str(peer), str(peer)


async def _close(writer: asyncio.StreamWriter) -> None:
    if not writer.is_closing():
        writer.close()
    with contextlib.suppress(Exception):
        await writer.wait_closed()


def _tls_reason(exc: ssl_module.SSLError) -> str:
    """'certificate verify failed: self-signed certificate', not the '[SSL: ...] ... (_ssl.c:N)'."""
    if isinstance(exc, ssl_module.SSLCertVerificationError) and exc.verify_message:
        return f"certificate verify failed: {exc.verify_message}"
    if exc.reason:
        return str(exc.reason).lower().replace("_", " ")
    return str(exc) or type(exc).__name__


@dataclass(eq=False)
class _CtcLink:
    pump: SessionPump
    conn: CtcConnection
    host: str
    peer: str
    station: int | None = None
    pending: dict[int, deque[asyncio.Future[ev.ControlAnswered]]] = field(default_factory=dict)


class CtcServer(Waitable):
    """The CTC's Type II server: admits IXLs, hands their indications to `app`, sends controls.

    `admission`: an AdmissionPolicy, or just the configured station numbers. `app` learns each
    station's link and indications (see `CtcApplication`). `port` 0 picks a free port (read it
    back from `port` after `start()`). `ssl`: a server-side SSLContext for type2-tls.
    `on_event(station, event)` sees every session event after the server and `app` acted on it.
    """

    def __init__(
        self,
        admission: AdmissionPolicy | Iterable[int],
        app: CtcApplication,
        *,
        host: str = DEFAULT_HOST,
        port: int = 0,
        config: Type2Config | None = None,
        ssl: ssl_module.SSLContext | None = None,
        on_event: EventCallback | None = None,
    ) -> None:
        self.admission = (
            admission if isinstance(admission, AdmissionPolicy) else AdmissionPolicy(admission)
        )
        self.app = app
        self.host = host
        self._port = port
        self.config = config or Type2Config()
        self.ssl = ssl
        self.on_event = on_event
        self._links: dict[int, _CtcLink] = {}  # identified connections by station
        self._all: set[_CtcLink] = set()
        self._tasks: set[asyncio.Task[None]] = set()
        self._handshaking: set[asyncio.Task[None]] = set()  # connections still in the TLS handshake
        self._stopping = False
        self._server: net.Server | None = None
        self._waiters: list[asyncio.Future[None]] = []
        self.refusals: list[tuple[str, str]] = []  # (peer, reason), newest last

    # -- lifecycle -----------------------------------------------------------------------------
    async def start(self) -> None:
        # plain TCP even for type2-tls: `_serve` upgrades after the address check, so a failed
        # handshake is a refusal logged with the peer's address (SPEC §10), not a silent drop
        self._server = await net.start_server(
            self._serve, self.host, self._port, reuse_address=True
        )
        log.info("Type II CTC listening on %s:%s", self.host, self.port)

    @property
    def port(self) -> int:
        if self._server is None or not self._server.sockets:
            raise UsageError("the CTC server is not started")
        return net.server_address(self._server)[1]

    async def close(self) -> None:
        self._stopping = True
        if self._server is not None:
            self._server.close()
        for task in list(self._handshaking):
            task.cancel()
        for cl in list(self._all):
            cl.pump.feed(cl.conn.close("CTC shutting down"))
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> CtcServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- commands ------------------------------------------------------------------------------
    def send_control(self, station: int, items: Iterable[tuple[int, int]]) -> None:
        """CONTROL items (control code, value) to a connected station; raises UsageError if it is not."""
        cl = self._link_of(station)
        cl.conn.send_control(items, cl.pump.now())
        cl.pump.flush()

    async def control(
        self, station: int, code: int, value: int = 1, timeout: float = 5.0
    ) -> ev.ControlAnswered:
        """Send one control and wait for its CONTROL_RESULT (TimeoutError after `timeout`)."""
        cl = self._link_of(station)
        fut: asyncio.Future[ev.ControlAnswered] = asyncio.get_running_loop().create_future()
        cl.pending.setdefault(code, deque()).append(fut)
        self.send_control(station, [(code, value)])
        try:
            return await asyncio.wait_for(fut, timeout)
        finally:
            queue = cl.pending.get(code)
            if queue and fut in queue:
                queue.remove(fut)

    def request_all(self, station: int) -> None:
        cl = self._link_of(station)
        cl.conn.request_all(cl.pump.now())
        cl.pump.flush()

    def disconnect(self, station: int, reason: str = "closed by the CTC") -> None:
        cl = self._links.get(station)
        if cl is not None:
            cl.pump.feed(cl.conn.close(reason))

    def _link_of(self, station: int) -> _CtcLink:
        cl = self._links.get(station)
        if cl is None or not cl.conn.identified:
            raise UsageError(f"station {station} is not connected")
        return cl

    # -- one connection ------------------------------------------------------------------------
    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        try:
            host, peer = _peer_name(writer)
            decision = self.admission.check_address(host)
            if not decision:
                self._refused(peer, decision.reason)
                await _close(writer)
                return
            if self.ssl is not None:
                self._handshaking.add(task)
                try:
                    failure = await self._handshake(writer)
                except asyncio.CancelledError:
                    if not self._stopping:
                        raise
                    task.uncancel()  # close() cut it short: end quietly (3.11 logs a cancelled one)
                    failure = "CTC shutting down"
                finally:
                    self._handshaking.discard(task)
                if failure is not None:
                    self._refused(peer, f"TLS handshake failed: {failure}")
                    # the loop already closed the socket; not wait_closed(): a handshake cut
                    # short never tells the stream protocol, so that would wait forever (3.11)
                    if not writer.is_closing():
                        writer.close()
                    return
            conn = CtcConnection(asyncio.get_running_loop().time(), self.config)
            meter = self.admission.bad_frame_meter()
            holder: list[_CtcLink] = []

            def on_events(events: list[ev.SessionEvent]) -> None:
                self._on_events(holder[0], meter, events)

            cl = _CtcLink(SessionPump(conn, reader, writer, on_events), conn, host, peer)
            holder.append(cl)
            self._all.add(cl)
            log.info("Type II connection from %s", peer)
            try:
                await cl.pump.run()
            finally:
                self._all.discard(cl)
                self._detach(cl)
        finally:
            self._tasks.discard(task)

    async def _handshake(self, writer: asyncio.StreamWriter) -> str | None:
        """Upgrade the accepted stream to TLS in place (the same reader and writer carry on).

        Bounded by the IDENT timeout (the handshake is part of getting to IDENT); None when it
        succeeded, else a short reason.
        """
        assert self.ssl is not None
        timeout = self.config.ident_timeout
        try:
            async with asyncio.timeout(timeout):
                await writer.start_tls(self.ssl)
        except ssl_module.SSLError as exc:
            return _tls_reason(exc)
        except TimeoutError:
            return f"no handshake within {timeout:g} s"
        except (ConnectionError, OSError) as exc:
            if str(exc):
                return str(exc)
            return "closed by the peer" if isinstance(exc, ConnectionResetError) else repr(exc)
        return None

    def _refused(self, peer: str, reason: str) -> None:
        log.warning("Type II: refused %s: %s", peer, reason)
        self.refusals.append((peer, reason))
        self._notify()

    def _detach(self, cl: _CtcLink) -> None:
        st = cl.station
        if st is not None and self._links.get(st) is cl:
            del self._links[st]
            self.app.link_down(st)
            for queue in cl.pending.values():
                for fut in queue:
                    if not fut.done():
                        fut.set_exception(PeerError(f"station {st} disconnected"))
            self._notify()

    def _on_events(self, cl: _CtcLink, meter: BadFrameMeter, events: list[ev.SessionEvent]) -> None:
        conn = cl.conn
        now = cl.pump.now()
        for e in events:
            if isinstance(e, ev.IndicationsChanged):
                if cl.station is not None:
                    self.app.indications(cl.station, e.items)
            elif isinstance(e, ev.FullState):
                if cl.station is not None:
                    self.app.full_state(cl.station, e.items)
            elif isinstance(e, ev.ControlAnswered):
                queue = cl.pending.get(e.code)
                if queue:
                    fut = queue.popleft()
                    if not fut.done():
                        fut.set_result(e)
            elif isinstance(e, ev.IdentRequested):
                self._ident(cl, e, now)
            elif isinstance(e, ev.BadFrameReceived):
                decision = meter.record(now)
                if not decision and not conn.closed:
                    self._refused(cl.peer, f"dropped: {decision.reason}")
                    conn.close("repeated bad frames")
            elif isinstance(e, ev.Closed):
                log.info("Type II %s (station %s) closed: %s", cl.peer, cl.station, e.reason)
            if self.on_event is not None:
                try:
                    self.on_event(cl.station, e)
                except Exception:  # a faulty observer must not take the link down
                    log.exception("Type II on_event callback failed for %r", e)
        self._notify()

    def _ident(self, cl: _CtcLink, e: ev.IdentRequested, now: float) -> None:
        connected = [st for st, other in self._links.items() if other.conn.identified]
        decision = self.admission.check_ident(e.station, e.version, cl.host, connected)
        if not decision:
            self._refused(cl.peer, decision.reason)
            cl.conn.refuse(now, decision.reason)
            return
        cl.conn.accept(now)
        cl.station = e.station
        self._links[e.station] = cl
        self.app.link_up(e.station, cl.peer)
        log.info("Type II station %s identified from %s", e.station, cl.peer)
