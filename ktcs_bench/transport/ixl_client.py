"""The IXL's Type II client: connect to the CTC, IDENT, serve the interlocking, back off, reconnect.

`IxlClient` runs one `IxlSession` per connection through a `SessionPump`; what it sends comes
from its `IxlApplication` (the interlocking, or the plain `StateTable`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl as ssl_module
from collections.abc import Callable, Iterable, Mapping
from typing import Protocol

from ktcs_bench.errors import UsageError
from ktcs_bench.transport import net
from ktcs_bench.transport.type2_pump import EventCallback, SessionPump, Waitable
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ixl_side import IxlSession

log = logging.getLogger("ktcs_bench.type2")

REJECT_UNKNOWN_CODE = 6  # CONTROL_RESULT reason "unknown code" in protocols/type2.yaml


class IxlApplication(Protocol):
    """What the IXL client needs from the interlocking it serves."""

    def full_state(self) -> Iterable[tuple[int, int]]:
        """Every indication code's state, (code number, state), in chart order."""
        ...

    def on_control(self, code: int, value: int) -> tuple[bool, int] | None:
        """Act on one CTC control: (accepted, reason) -- reason 0 when accepted; None when the
        answer comes later (`IxlClient.control_result`)."""
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

    def on_control(self, code: int, value: int) -> tuple[bool, int] | None:
        if self._control is None:
            return False, REJECT_UNKNOWN_CODE
        return self._control(code, value)


class IxlClient(Waitable):
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
        self._pump: SessionPump | None = None
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
        if self._pump is not None and self._session is not None:
            self._pump.feed(self._session.close("IXL shutting down"))
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
        if self._pump is not None and self._session is not None:
            self._pump.feed(self._session.close(reason))

    # -- late answers ----------------------------------------------------------------------------
    def control_result(self, code: int, accepted: bool, reason: int) -> None:
        """Answer a control the application answered None to, now that its answer is here. A
        connection lost meanwhile took the control with it: nothing is sent."""
        session, pump = self._session, self._pump
        if session is None or pump is None or not session.identified or session.closed:
            return
        session.send_control_result(code, accepted, reason, pump.now())
        pump.flush()

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
        session, pump = self._session, self._pump
        if pending and session is not None and pump is not None and session.identified:
            session.send_indications(pending, pump.now())
            pump.flush()

    async def drain(self) -> None:
        """Wait while the socket's send buffer is full (back-pressure for bulk producers)."""
        if self._pump is not None:
            await self._pump.drain()

    # -- the connection loop -------------------------------------------------------------------
    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        backoff = self.backoff_initial
        while not self._closing:
            self.attempts += 1
            try:
                reader, writer = await net.open_connection(
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
                pump = SessionPump(session, reader, writer, self._on_events)
                self._session, self._pump = session, pump
                accepted_before = self.connections
                try:
                    await pump.run()
                finally:
                    self._session = self._pump = None
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

    def _on_events(self, events: list[ev.SessionEvent]) -> None:
        try:
            self._handle_events(events)
        except Exception:  # the application failed: log it, drop this connection, reconnect
            log.exception("Type II station %s: application error; closing the link", self.station)
            if self._session is not None:
                self._session.close("application error")
        self._notify()

    def _handle_events(self, events: list[ev.SessionEvent]) -> None:
        session, pump = self._session, self._pump
        assert session is not None and pump is not None
        for e in events:
            if isinstance(e, ev.IdentAccepted | ev.FullStateRequested):
                if isinstance(e, ev.IdentAccepted):
                    self.connections += 1
                self._pending = []  # the full state supersedes queued changes
                session.send_full_state(self.app.full_state(), pump.now())
            elif isinstance(e, ev.ControlRequested):
                for code, value in e.items:
                    answer = self.app.on_control(code, value)
                    if session.closed:
                        break
                    if answer is not None:  # None: answered later (`control_result`)
                        session.send_control_result(code, *answer, pump.now())
            elif isinstance(e, ev.IdentRefused):
                log.warning("Type II station %s: refused by the CTC at %s:%s",
                            self.station, self.host, self.port)  # fmt: skip
            if self.on_event is not None:
                self.on_event(self.station, e)
