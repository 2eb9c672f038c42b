"""The pty adapter: a tap between two pty pairs, for a Type I link.

Device a opens `paths[a]`, device b opens `paths[b]`; the tap reads both masters and writes what
the core delivers to the other one. A pty nobody reads keeps at most PTY_PENDING_MAX bytes queued
(the oldest are dropped and counted). `cut` loses the bytes (the core's fault injectors do it).

An end may instead be a real device's serial line (`external={end: URL}`: a device path, a pty
path or any pyserial URL such as `rfc2217://host:port`): the tap opens it itself, writes to it
paced at the line rate, reads it in a thread of its own, and reopens it every REOPEN seconds
when it cannot be opened or goes away (the device off, the serial server across the network
down). What the core delivers to an end that is not open is lost, as on a line with nothing on it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
import tty
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypedDict

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.tap.core import TapEvent
from ktcs_bench.tap.registry import TapEnds
from ktcs_bench.tap.runner import Tap, TapStatus
from ktcs_bench.transport.base import TransportClosed
from ktcs_bench.transport.serialport import SerialTransport
from ktcs_bench.type1.config import LINE_RATE

PTY_PENDING_MAX = 1 << 20  # bytes queued for a pty nobody reads before the oldest are dropped
REOPEN = 1.0  # s between attempts to open an external serial end that is not there
JOIN_TIMEOUT = 10.0  # s; an open in progress (an RFC 2217 server negotiating) ends first
POLL = 0.05  # s, how long the reader of an external end waits before it checks for stop


@dataclass
class _Pty:
    master: int
    slave: int
    path: str
    pending: bytearray = field(default_factory=bytearray)
    writing: bool = False
    dropped: int = 0


class ExternalEnd(TypedDict):
    """An external end in a pty tap's status: open or why not, how often opened, bytes lost."""

    endpoint: str
    open: bool
    error: str | None
    opens: int
    dropped: int


class PtyStatus(TapStatus):
    """A pty tap's status, with external ends: how each one is."""

    external_ends: dict[str, ExternalEnd]


@dataclass
class _Serial:
    """An end that is a real device's serial line, opened by the tap."""

    endpoint: str
    transport: SerialTransport | None = None
    error: str | None = None
    opens: int = 0
    dropped: int = 0
    thread: threading.Thread | None = None


class PtyTap(Tap):
    """A tap between two ptys: device a opens `paths[a]`, device b opens `paths[b]`.

    with PtyTap(names=("ixl", "atc")) as tap:
        ixl = serial.Serial(tap.paths["ixl"]); atc = serial.Serial(tap.paths["atc"])
    """

    kind = "pty"

    def __init__(
        self,
        *,
        external: Mapping[str, str] | None = None,
        line_rate: float | None = LINE_RATE,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self._ptys: dict[str, _Pty] = {}
        self._serials = {end: _Serial(url) for end, url in (external or {}).items()}
        if set(self._serials) - set(self.names):
            raise UsageError(f"external ends {sorted(self._serials)} are not {self.names}")
        self.line_rate = line_rate  # what an external end is written at (None: as it comes)
        self._stopping = threading.Event()
        # open the ptys now, so `paths` is known before start()
        try:
            for end in self.names:
                if end in self._serials:
                    continue
                master, slave = os.openpty()
                tty.setraw(slave)
                os.set_blocking(master, False)
                self._ptys[end] = _Pty(master, slave, os.ttyname(slave))
        except OSError as exc:
            self._close_fds()
            raise PeerError(f"cannot create a pty: {exc}") from None

    @property
    def paths(self) -> dict[str, str]:
        """The pty path of each end the tap made (an external end has none)."""
        return {end: p.path for end, p in self._ptys.items()}

    @property
    def external(self) -> dict[str, str]:
        """The serial endpoint of each external end."""
        return {end: s.endpoint for end, s in self._serials.items()}

    def external_open(self, end: str) -> bool:
        s = self._serials.get(end)
        return s is not None and s.transport is not None

    def _ends_info(self) -> TapEnds:
        ends: TapEnds = {"paths": self.paths}
        if self._serials:
            ends["external"] = self.external
        return ends

    def _status(self) -> TapStatus | PtyStatus:
        out = super()._status()
        if not self._serials:
            return out
        ends: dict[str, ExternalEnd] = {
            end: {"endpoint": s.endpoint, "open": s.transport is not None, "error": s.error,
                  "opens": s.opens, "dropped": s.dropped}
            for end, s in self._serials.items()
        }  # fmt: skip
        return {**out, "external_ends": ends}

    def external_error(self, end: str) -> str | None:
        """Why external end `end` is not open (None: it is, or it has no error yet)."""
        return self._call(lambda: self._serials[end].error)

    def _other(self, end: str) -> str:
        return self.names[1] if end == self.names[0] else self.names[0]

    async def _open_ends(self) -> None:
        loop = asyncio.get_running_loop()
        for end, p in self._ptys.items():
            loop.add_reader(p.master, self._readable, end)
        for end, s in self._serials.items():
            # the first attempt before the tap is up, so its status says at once whether the
            # device is there; a reader thread of its own from then on
            self._set_open(end, *await asyncio.to_thread(self._try_open, s))
            s.thread = threading.Thread(
                target=self._serial_main,
                args=(end, loop),
                name=f"tap-{self.name}-{end}",
                daemon=True,
            )
            s.thread.start()

    # -- external ends (the reader thread owns opening and closing; the loop only writes) ------
    def _try_open(self, s: _Serial) -> tuple[SerialTransport | None, str | None]:
        try:
            return SerialTransport(s.endpoint, f"{self.name}-{s.endpoint}", self.line_rate), None
        except (TransportClosed, OSError, ValueError) as exc:
            return None, str(exc)

    def _set_open(self, end: str, transport: SerialTransport | None, error: str | None) -> None:
        """In the loop: an external end opened (transport) or is not there (error)."""
        s = self._serials[end]
        was_open, was_error = s.transport is not None, s.error
        s.transport, s.error = transport, error
        if transport is not None:
            s.opens += 1
            opened: TapEvent = {"event": "opened", "end": end, "endpoint": s.endpoint}
            self._apply(self.core.note(self._now(), opened))
        elif was_open or error != was_error:  # said once, not at every attempt
            closed: TapEvent = {"event": "closed", "end": end, "endpoint": s.endpoint,
                                "error": error}  # fmt: skip
            self._apply(self.core.note(self._now(), closed))

    def _serial_main(self, end: str, loop: asyncio.AbstractEventLoop) -> None:
        s, direction = self._serials[end], f"{end}>{self._other(end)}"

        def tell(fn: Any, *args: Any) -> None:
            with contextlib.suppress(RuntimeError):  # the loop is closing
                loop.call_soon_threadsafe(fn, *args)

        transport = s.transport
        while not self._stopping.is_set():
            if transport is None:
                if self._stopping.wait(REOPEN):
                    break
                transport, error = self._try_open(s)
                tell(self._set_open, end, transport, error)
                continue
            try:
                data = transport.recv(POLL)
            except (TransportClosed, OSError) as exc:
                tell(self._set_open, end, None, str(exc))
                transport.close()
                transport = None
                continue
            if data:
                tell(self._on_data, direction, data)
        if transport is not None:
            transport.close()

    def _readable(self, end: str) -> None:
        p = self._ptys[end]
        try:
            data = os.read(p.master, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: no slave open (cannot happen while we hold one), be quiet
            return
        if data:
            self._on_data(f"{end}>{self._other(end)}", data)

    def _deliver(self, direction: str, data: bytes) -> None:
        end = direction.split(">", 1)[1]
        if end in self._serials:
            s = self._serials[end]
            try:
                if s.transport is None:
                    raise TransportClosed("not open")
                s.transport.send(data)  # queued, written at the line rate by its writer
            except TransportClosed:
                s.dropped += len(data)
            return
        p = self._ptys[end]
        p.pending += data
        if len(p.pending) > PTY_PENDING_MAX:
            extra = len(p.pending) - PTY_PENDING_MAX
            del p.pending[:extra]
            p.dropped += extra
        self._flush(end)

    def _flush(self, end: str) -> None:
        p = self._ptys[end]
        loop = asyncio.get_running_loop()
        while p.pending:
            try:
                n = os.write(p.master, p.pending)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                p.dropped += len(p.pending)
                p.pending.clear()
                break
            if n == 0:
                if not p.writing:
                    loop.add_writer(p.master, self._flush, end)
                    p.writing = True
                return
            del p.pending[:n]
        if p.writing:
            loop.remove_writer(p.master)
            p.writing = False

    async def _close_ends(self) -> None:
        loop = asyncio.get_running_loop()
        self._stopping.set()
        for s in self._serials.values():
            if s.thread is not None:
                await asyncio.to_thread(s.thread.join, JOIN_TIMEOUT)
            elif s.transport is not None:
                s.transport.close()
            s.transport = None
        for p in self._ptys.values():
            loop.remove_reader(p.master)
            if p.writing:
                loop.remove_writer(p.master)
        self._close_fds()

    def _close_fds(self) -> None:
        for p in self._ptys.values():
            for fd in (p.master, p.slave):
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._ptys.clear()

    def __del__(self) -> None:
        if self._ptys and self._loop is None and self._thread is None:
            self._close_fds()
