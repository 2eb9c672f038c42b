"""The asyncio pump that binds one sans-I/O Type II session to one stream pair.

`SessionPump` only moves bytes between the stream and the session, feeds it the loop's clock,
leaves its deadline to the wall-clock driver (`ktcs_bench.timed.aio.LoopTimer`) and hands its
events on; `Waitable` lets the server and
the client offer `wait_until(predicate)`, re-checked after every event. Everything the protocol
decides is decided in the session (`ctc_side`, `ixl_side`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl as ssl_module
from collections.abc import Callable

from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.session import Type2Session

log = logging.getLogger("ktcs_bench.type2")

READ_SIZE = 1 << 16

EventCallback = Callable[[int | None, ev.SessionEvent], None]
"""(station or None before IDENT, event) -- every session event, after the adapter acted on it."""


class SessionPump:
    """One session bound to one stream pair and the loop clock."""

    def __init__(
        self,
        session: Type2Session,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        on_events: Callable[[list[ev.SessionEvent]], None],
    ) -> None:
        self.session = session
        self.reader = reader
        self.writer = writer
        self.on_events = on_events
        self.loop = asyncio.get_running_loop()
        self.timer = LoopTimer(session, lambda now, events: self.feed(events))

    def now(self) -> float:
        return self.loop.time()

    def feed(self, events: list[ev.SessionEvent]) -> None:
        if events:
            self.on_events(events)
        self.flush()

    def flush(self) -> None:
        data = self.session.data_to_send()
        if data and not self.writer.is_closing():
            self.writer.write(data)
        if self.session.closed:
            self.timer.cancel()
            if not self.writer.is_closing():
                self.writer.close()
            return
        self.timer.poke()

    async def drain(self) -> None:
        """Wait while the socket's send buffer is full (back-pressure for bulk producers)."""
        if self.writer.is_closing():
            return
        if self.writer.transport.get_write_buffer_size() > READ_SIZE:
            with contextlib.suppress(ConnectionError, OSError):
                await self.writer.drain()

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
                await self.drain()
        finally:
            self.timer.cancel()
            if not session.closed:
                self.on_events(session.connection_lost(self.now()))
            self.session.data_to_send()
            if not self.writer.is_closing():
                self.writer.close()
            with contextlib.suppress(Exception):
                await self.writer.wait_closed()


class Waitable:
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
