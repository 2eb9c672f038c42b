"""asyncio adapters for Type II: the CTC server and the IXL client, over TCP (optionally TLS).

They only move bytes between a stream and a sans-I/O session, feed it the loop's clock, honour its
deadline with one timer handle, and hand its events to the application. Everything the protocol
decides is decided in `ctc_side` / `ixl_side`; who may connect is decided in `admission`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl as ssl_module
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.admission import AdmissionPolicy, BadFrameMeter
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ctc_side import CtcConnection
from ktcs_bench.type2.ixl_side import IxlSession
from ktcs_bench.type2.session import Type2Session

log = logging.getLogger("ktcs_bench.type2")

DEFAULT_HOST = "127.0.0.1"  # SPEC §10: binding anywhere else is an explicit choice
READ_SIZE = 1 << 16
REJECT_UNKNOWN_CODE = 6  # CONTROL_RESULT reason "unknown code" in protocols/type2.yaml

EventCallback = Callable[[int | None, ev.Event], None]
"""(station or None before IDENT, event) -- every session event, after the adapter acted on it."""


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


class _Link:
    """One session bound to one stream pair and the loop clock."""

    def __init__(
        self,
        session: Type2Session,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        on_events: Callable[[list[ev.Event]], None],
    ) -> None:
        self.session = session
        self.reader = reader
        self.writer = writer
        self.on_events = on_events
        self.loop = asyncio.get_running_loop()
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None

    def now(self) -> float:
        return self.loop.time()

    def feed(self, events: list[ev.Event]) -> None:
        if events:
            self.on_events(events)
        self.flush()

    def flush(self) -> None:
        data = self.session.data_to_send()
        if data and not self.writer.is_closing():
            self.writer.write(data)
        if self.session.closed:
            self._cancel_timer()
            if not self.writer.is_closing():
                self.writer.close()
            return
        deadline = self.session.next_deadline()
        if deadline != self._timer_at:
            self._cancel_timer()
            if deadline is not None:
                self._timer = self.loop.call_at(deadline, self._on_timer)
                self._timer_at = deadline

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._timer = None
        self._timer_at = None

    def _on_timer(self) -> None:
        self._timer = None
        self._timer_at = None
        self.feed(self.session.handle_timer(self.now()))

    async def run(self) -> None:
        """Until the session closes or the transport goes away."""
        session = self.session
        self.flush()
        try:
            while not session.closed:
                try:
                    data = await self.reader.read(READ_SIZE)
                except (ConnectionError, OSError, ssl_module.SSLError) as exc:
                    log.debug("Type II read failed: %s", exc)
                    data = b""
                if not data:
                    self.feed(session.connection_lost(self.now()))
                    break
                self.feed(session.receive_data(data, self.now()))
                if self.writer.transport.get_write_buffer_size() > READ_SIZE:
                    with contextlib.suppress(ConnectionError, OSError):
                        await self.writer.drain()
        finally:
            self._cancel_timer()
            if not session.closed:
                self.on_events(session.connection_lost(self.now()))
            self.session.data_to_send()
            if not self.writer.is_closing():
                self.writer.close()
            with contextlib.suppress(Exception):
                await self.writer.wait_closed()


# ---------------------------------------------------------------------------------------------
# CTC server


@dataclass
class StationView:
    """What the CTC knows of one station: its indications and its link."""

    station: int
    state: dict[int, int] = field(default_factory=dict)
    connected: bool = False
    synced: bool = False  # a full state arrived on the current connection
    peer: str | None = None
    connections: int = 0  # accepted connections so far
    full_states: int = 0  # full-state dumps received so far


@dataclass(eq=False)
class _CtcLink:
    link: _Link
    conn: CtcConnection
    host: str
    peer: str
    station: int | None = None
    pending: dict[int, deque[asyncio.Future[ev.ControlAnswered]]] = field(default_factory=dict)


class _Waitable:
    """`wait_until(predicate)` for the server and the client: re-checked after every event."""

    _waiters: list[asyncio.Future[None]]

    async def wait_until(self, predicate: Callable[[], bool], timeout: float = 10.0) -> None:
        """Wait until `predicate()` holds, re-checked after every event (TimeoutError otherwise)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while not predicate():
            left = deadline - loop.time()
            if left <= 0:
                raise TimeoutError("condition not reached")
            fut: asyncio.Future[None] = loop.create_future()
            self._waiters.append(fut)
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(left):  # not wait_for: it may swallow a cancel (3.11)
                    await fut

    def _notify(self) -> None:
        waiters, self._waiters = self._waiters, []
        for w in waiters:
            if not w.done():
                w.set_result(None)


class CtcServer(_Waitable):
    """The CTC's Type II server: admits IXLs, keeps each station's indication state, sends controls.

    `admission`: an AdmissionPolicy, or just the configured station numbers. `port` 0 picks a free
    port (read it back from `port` after `start()`). `ssl`: a server-side SSLContext for type2-tls.
    `on_event(station, event)` sees every session event after the server acted on it.
    """

    def __init__(
        self,
        admission: AdmissionPolicy | Iterable[int],
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
        self.host = host
        self._port = port
        self.config = config or Type2Config()
        self.ssl = ssl
        self.on_event = on_event
        self.stations: dict[int, StationView] = {
            st: StationView(st) for st in sorted(self.admission.stations)
        }
        self._links: dict[int, _CtcLink] = {}  # identified connections by station
        self._all: set[_CtcLink] = set()
        self._tasks: set[asyncio.Task[None]] = set()
        self._handshaking: set[asyncio.Task[None]] = set()  # connections still in the TLS handshake
        self._stopping = False
        self._server: asyncio.Server | None = None
        self._waiters: list[asyncio.Future[None]] = []
        self.refusals: list[tuple[str, str]] = []  # (peer, reason), newest last

    # -- lifecycle -----------------------------------------------------------------------------
    async def start(self) -> None:
        # plain TCP even for type2-tls: `_serve` upgrades after the address check, so a failed
        # handshake is a refusal logged with the peer's address (SPEC §10), not a silent drop
        self._server = await asyncio.start_server(
            self._serve, self.host, self._port, reuse_address=True
        )
        log.info("Type II CTC listening on %s:%s", self.host, self.port)

    @property
    def port(self) -> int:
        if self._server is None or not self._server.sockets:
            raise UsageError("the CTC server is not started")
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        self._stopping = True
        if self._server is not None:
            self._server.close()
        for task in list(self._handshaking):
            task.cancel()
        for cl in list(self._all):
            cl.link.feed(cl.conn.close("CTC shutting down"))
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
        cl.conn.send_control(items, cl.link.now())
        cl.link.flush()

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
        cl.conn.request_all(cl.link.now())
        cl.link.flush()

    def disconnect(self, station: int, reason: str = "closed by the CTC") -> None:
        cl = self._links.get(station)
        if cl is not None:
            cl.link.feed(cl.conn.close(reason))

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

            def on_events(events: list[ev.Event]) -> None:
                self._on_events(holder[0], meter, events)

            cl = _CtcLink(_Link(conn, reader, writer, on_events), conn, host, peer)
            holder.append(cl)
            self._all.add(cl)
            log.info("Type II connection from %s", peer)
            try:
                await cl.link.run()
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
            view = self.stations[st]
            view.connected = False
            view.synced = False
            for queue in cl.pending.values():
                for fut in queue:
                    if not fut.done():
                        fut.set_exception(PeerError(f"station {st} disconnected"))
            self._notify()

    def _on_events(self, cl: _CtcLink, meter: BadFrameMeter, events: list[ev.Event]) -> None:
        conn = cl.conn
        now = cl.link.now()
        for e in events:
            if isinstance(e, ev.IndicationsChanged):
                if cl.station is not None:
                    self.stations[cl.station].state.update(e.items)
            elif isinstance(e, ev.FullState):
                if cl.station is not None:
                    view = self.stations[cl.station]
                    view.state = dict(e.items)
                    view.synced = True
                    view.full_states += 1
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
        view = self.stations[e.station]
        view.connected = True
        view.synced = False
        view.peer = cl.peer
        view.connections += 1
        log.info("Type II station %s identified from %s", e.station, cl.peer)


# ---------------------------------------------------------------------------------------------
# IXL client


class IxlApplication(Protocol):
    """What the IXL client needs from the interlocking it serves."""

    def full_state(self) -> Iterable[tuple[int, int]]:
        """Every indication code's state, (code number, state), in chart order."""
        ...

    def on_control(self, code: int, value: int) -> tuple[bool, int]:
        """Act on one CTC control: (accepted, reason) -- reason 0 when accepted."""
        ...


class StateTable:
    """A plain IxlApplication: a code -> state table, and a control handler (default: refuse all).

    Stands in for the interlocking until the real one is plugged in; tests and benchmarks use it.
    """

    def __init__(
        self,
        state: Mapping[int, int],
        control: Callable[[int, int], tuple[bool, int]] | None = None,
    ) -> None:
        self.state = dict(state)
        self._control = control

    def full_state(self) -> list[tuple[int, int]]:
        return sorted(self.state.items())

    def on_control(self, code: int, value: int) -> tuple[bool, int]:
        if self._control is None:
            return False, REJECT_UNKNOWN_CODE
        return self._control(code, value)


class IxlClient(_Waitable):
    """Station `station`'s IXL link to the CTC at host:port: connect, IDENT, serve, reconnect.

    Reconnects after every loss with exponential back-off from `backoff_initial` doubling up to
    `backoff_max` (reset once a connection is accepted). On every accepted connection, and on
    REQUEST_ALL, it sends `app.full_state()`; CONTROL items go to `app.on_control`. Push changes
    with `indicate()`: they are sent together at the next turn of the event loop, or, with
    `indication_delay` > 0, gathered for that long first (fewer, fuller messages -- the IXL's
    indication cycle).
    """

    session_class: type[IxlSession] = IxlSession  # hook: a test variant may subclass the session

    def __init__(
        self,
        station: int,
        host: str,
        port: int,
        app: IxlApplication,
        *,
        config: Type2Config | None = None,
        ssl: ssl_module.SSLContext | None = None,
        server_hostname: str | None = None,
        backoff_initial: float = 0.1,
        backoff_max: float = 5.0,
        indication_delay: float = 0.0,
        on_event: EventCallback | None = None,
    ) -> None:
        if indication_delay < 0:
            raise UsageError("indication_delay cannot be negative")
        if not 0 < backoff_initial <= backoff_max:
            raise UsageError("back-off needs 0 < backoff_initial <= backoff_max")
        self.station = station
        self.host = host
        self.port = port
        self.app = app
        self.config = config or Type2Config()
        self.ssl = ssl
        self.server_hostname = server_hostname
        self.backoff_initial = backoff_initial
        self.backoff_max = backoff_max
        self.indication_delay = indication_delay
        self.on_event = on_event
        self.connections = 0  # accepted (identified) connections so far
        self.attempts = 0  # TCP connection attempts so far
        self._link: _Link | None = None
        self._session: IxlSession | None = None
        self._pending: list[tuple[int, int]] = []
        self._flush_scheduled = False
        self._task: asyncio.Task[None] | None = None
        self._closing = False
        self._waiters: list[asyncio.Future[None]] = []

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run())

    async def close(self) -> None:
        self._closing = True
        if self._link is not None and self._session is not None:
            self._link.feed(self._session.close("IXL shutting down"))
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def __aenter__(self) -> IxlClient:
        self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def identified(self) -> bool:
        return self._session is not None and self._session.identified

    @property
    def session(self) -> IxlSession | None:
        return self._session

    def drop_connection(self, reason: str = "dropped locally") -> None:
        """Close the current connection (the client reconnects)."""
        if self._link is not None and self._session is not None:
            self._link.feed(self._session.close(reason))

    # -- pushing indications -------------------------------------------------------------------
    def indicate(self, changes: Iterable[tuple[int, int]]) -> None:
        """Queue change indications; update the state `app.full_state()` reads before calling.

        While not connected they are dropped: the full state sent on reconnection carries them.
        """
        if not self.identified:
            return
        self._pending.extend(changes)
        if not self._flush_scheduled:
            self._flush_scheduled = True
            loop = asyncio.get_running_loop()
            if self.indication_delay:
                loop.call_later(self.indication_delay, self._flush_pending)
            else:
                loop.call_soon(self._flush_pending)

    def _flush_pending(self) -> None:
        self._flush_scheduled = False
        pending, self._pending = self._pending, []
        session, link = self._session, self._link
        if pending and session is not None and link is not None and session.identified:
            session.send_indications(pending, link.now())
            link.flush()

    async def drain(self) -> None:
        """Wait while the socket's send buffer is full (back-pressure for bulk producers)."""
        link = self._link
        if link is None or link.writer.is_closing():
            return
        if link.writer.transport.get_write_buffer_size() > READ_SIZE:
            with contextlib.suppress(ConnectionError, OSError):
                await link.writer.drain()

    # -- the connection loop -------------------------------------------------------------------
    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        backoff = self.backoff_initial
        while not self._closing:
            self.attempts += 1
            try:
                reader, writer = await asyncio.open_connection(
                    self.host,
                    self.port,
                    ssl=self.ssl,
                    server_hostname=self.server_hostname if self.ssl else None,
                )
            except (OSError, ssl_module.SSLError) as exc:
                log.info("Type II station %s: connect to %s:%s failed: %s",
                         self.station, self.host, self.port, exc)  # fmt: skip
                self._notify()
            else:
                session = self.session_class(self.station, loop.time(), self.config)
                link = _Link(session, reader, writer, self._on_events)
                self._session, self._link = session, link
                accepted_before = self.connections
                try:
                    await link.run()
                finally:
                    self._session = self._link = None
                    self._pending = []
                    self._notify()
                if self.connections > accepted_before:
                    backoff = self.backoff_initial
                log.info("Type II station %s: connection ended: %s", self.station,
                         session.close_reason)  # fmt: skip
            if self._closing:
                break
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, self.backoff_max)

    def _on_events(self, events: list[ev.Event]) -> None:
        try:
            self._handle_events(events)
        except Exception:  # the application failed: log it, drop this connection, reconnect
            log.exception("Type II station %s: application error; closing the link", self.station)
            if self._session is not None:
                self._session.close("application error")
        self._notify()

    def _handle_events(self, events: list[ev.Event]) -> None:
        session, link = self._session, self._link
        assert session is not None and link is not None
        for e in events:
            if isinstance(e, ev.IdentAccepted | ev.FullStateRequested):
                if isinstance(e, ev.IdentAccepted):
                    self.connections += 1
                self._pending = []  # the full state supersedes queued changes
                session.send_full_state(self.app.full_state(), link.now())
            elif isinstance(e, ev.ControlRequested):
                for code, value in e.items:
                    accepted, reason = self.app.on_control(code, value)
                    if session.closed:
                        break
                    session.send_control_result(code, accepted, reason, link.now())
            elif isinstance(e, ev.IdentRefused):
                log.warning("Type II station %s: refused by the CTC at %s:%s",
                            self.station, self.host, self.port)  # fmt: skip
            if self.on_event is not None:
                self.on_event(self.station, e)
