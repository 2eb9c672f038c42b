"""Runs a `Type1Link` over a `Transport` on the asyncio loop: the link's wall-clock adapter.

Owns: `LinkRunner`. It feeds the link what the transport reads (through `loop.add_reader` when the
transport has an fd, else a small reader thread), leaves the link's deadlines to the one
wall-clock driver (`ktcs_bench.timed.aio.LoopTimer`), and hands `data_to_send()` to the transport
after every call; a push-style transport (a virtual wire in a lab run in one process) hands its
bytes over itself. The clock is the loop's (monotonic) clock. Events go to `on_event(now, event)`
if given, else to the `events` queue.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable

from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.transport.base import PushTransport, Transport, TransportClosed
from ktcs_bench.type1 import LinkEvent, Message, Type1Link

EventSink = Callable[[float, LinkEvent], None]
POLL = 0.05  # s, reader-thread poll period for transports without an fd


class LinkRunner:
    """Drive `link` over `transport` inside a running asyncio loop: `await runner.run()`."""

    def __init__(
        self, link: Type1Link, transport: Transport, on_event: EventSink | None = None
    ) -> None:
        self.link = link
        self.transport = transport
        self.on_event = on_event
        self.events: asyncio.Queue[tuple[float, LinkEvent]] = asyncio.Queue()
        self.error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        # the timer re-arms itself after its sink: `_after` need not
        self.timer = LoopTimer(link, lambda now, events: self._after(events, now, poke=False))
        self._done: asyncio.Future[None] | None = None
        self._thread: threading.Thread | None = None
        self._stop_thread = threading.Event()

    # -- application side ----------------------------------------------------------------------
    def send(self, message: Message) -> None:
        """Queue an application message (call from the loop's thread)."""
        loop = self._require_loop()
        now = loop.time()
        self.link.send(message, now)
        self._after([], now)

    def stop(self) -> None:
        if self._done is not None and not self._done.done():
            self._done.set_result(None)

    async def next_event(self, *kinds: type, timeout: float | None = None) -> LinkEvent:
        """The next event from the queue (of the given classes, skipping others)."""
        async with asyncio.timeout(timeout):
            while True:
                _, event = await self.events.get()
                if not kinds or isinstance(event, kinds):
                    return event

    # -- the loop ------------------------------------------------------------------------------
    async def run(self) -> None:
        """Run until `stop()`, cancellation, or the transport closing (then re-raised)."""
        loop = self._loop = asyncio.get_running_loop()
        self._done = loop.create_future()
        fd = self.transport.fileno()
        if isinstance(self.transport, PushTransport):
            self.transport.attach(self._data, self._fail)
        elif fd is not None:
            loop.add_reader(fd, self._readable)
        else:
            self._thread = threading.Thread(target=self._reader, name="link-reader", daemon=True)
            self._thread.start()
        try:
            self.timer.fire()  # the line is open: the link starts its clock and announces itself
            await self._done
        finally:
            if fd is not None:
                loop.remove_reader(fd)
            self.timer.cancel()
            if self._thread is not None:
                self._stop_thread.set()
                await asyncio.to_thread(self._thread.join, 2.0)
        if self.error is not None:
            raise self.error

    # -- internals -----------------------------------------------------------------------------
    def _require_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise RuntimeError("LinkRunner.run() is not running")
        return self._loop

    def _readable(self) -> None:
        try:
            data = self.transport.recv(0)
        except TransportClosed as exc:
            self._fail(exc)
            return
        if data:
            self._data(data)

    def _data(self, data: bytes) -> None:
        loop = self._loop
        now = (loop if loop is not None else self._require_loop()).time()
        self._after(self.link.receive_data(data, now), now)

    def _reader(self) -> None:
        loop = self._require_loop()
        while not self._stop_thread.is_set():
            try:
                data = self.transport.recv(POLL)
            except TransportClosed as exc:
                loop.call_soon_threadsafe(self._fail, exc)
                return
            if data:
                loop.call_soon_threadsafe(self._data, data)

    def _after(self, events: list[LinkEvent], now: float, poke: bool = True) -> None:
        out = self.link.data_to_send(now)
        if out:
            try:
                self.transport.send(out)
            except TransportClosed as exc:
                self._fail(exc)
                return
        if events:
            on_event = self.on_event
            for event in events:
                if on_event is not None:
                    on_event(now, event)
                else:
                    self.events.put_nowait((now, event))
        if poke:
            self.timer.poke()

    def _fail(self, exc: BaseException) -> None:
        self.error = exc
        with contextlib.suppress(asyncio.InvalidStateError):
            self.stop()
