"""Serial-line transports: a pty pair, or any pyserial URL, with the sender paced at the line rate.

Owns: `PacedWriter` (a writer thread that releases bytes at `byte_time` each, in small bursts
against a monotonic schedule), `PtyTransport` (os.openpty(): we hold the master, a peer opens
`.path` with pyserial), `SerialTransport` (pyserial `serial_for_url`: a device path, `loop://`,
`socket://`, `rfc2217://`, or the slave side of a pty) and `open_transport(endpoint)`.

Pacing: a pty moves bytes as fast as the kernel can, so the bench paces the sender: byte k of a
busy period is released when it would have finished on a real 8N1 line, t0 + (k+1) × 10 / rate.
The writer sleeps until at least `burst` seconds of bytes are due (or the buffer is), then writes
them together -- never one sleep per byte. `line_rate=None` writes at once (for real hardware,
whose UART already paces).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import termios
import threading
import time
import tty
from typing import Any

import serial

from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.transport.base import TransportBase, TransportClosed
from ktcs_bench.transport.memory import VIRTUAL_SCHEME, MemorySerialTransport, network_of
from ktcs_bench.type1.config import BITS_PER_BYTE, LINE_RATE

BURST = 0.002  # s of line time written per wake-up at most; 2 bytes at 9600 bit/s
READ_SIZE = 4096
WRITE_TIMEOUT = 0.5  # s a write may block before the writer tries again


def byte_time_of(line_rate: float | None, bits_per_byte: int = BITS_PER_BYTE) -> float:
    return bits_per_byte / line_rate if line_rate else 0.0


class PacedWriter:
    """A daemon thread that writes queued bytes through `write` at `byte_time` per byte."""

    def __init__(self, write: Any, byte_time: float, name: str, burst: float = BURST) -> None:
        self._write = write  # callable(bytes) -> None, writes all of it or raises
        self.byte_time = byte_time
        self._burst_bytes = max(1, int(burst / byte_time)) if byte_time else 0
        self._buf = bytearray()
        self._cond = threading.Condition()
        self._line_free = 0.0  # monotonic time the bytes written so far finish on the line
        self._closed = False
        self.error: BaseException | None = None
        self.written = 0
        self._thread = threading.Thread(target=self._run, name=f"paced-{name}", daemon=True)
        self._thread.start()

    def write(self, data: bytes) -> None:
        if self.error is not None:
            raise TransportClosed(f"writer stopped: {self.error}")
        with self._cond:
            if self._closed:
                raise TransportClosed("transport closed")
            now = time.monotonic()
            if not self._buf and self._line_free < now:
                self._line_free = now  # the line was idle: a busy period starts now
            self._buf += data
            self._cond.notify()

    def drain(self, timeout: float | None = None) -> bool:
        """Wait until every queued byte has been written; False on timeout."""
        end = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while self._buf and self.error is None:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(2.0)

    def _run(self) -> None:
        bt = self.byte_time
        try:
            while True:
                with self._cond:
                    while not self._buf and not self._closed:
                        self._cond.wait()
                    if self._closed:
                        return
                    now = time.monotonic()
                    if bt:
                        due = min(len(self._buf), int((now - self._line_free) / bt + 1e-9))
                        if due == 0 or (due < len(self._buf) and due < self._burst_bytes):
                            want = min(len(self._buf), self._burst_bytes)
                            self._cond.wait(max(0.0, self._line_free + want * bt - now))
                            continue
                    else:
                        due = len(self._buf)
                    chunk = bytes(self._buf[:due])
                    del self._buf[:due]
                    self._line_free += due * bt
                    self._cond.notify_all()
                self._write(chunk)
                self.written += len(chunk)
        except BaseException as exc:  # noqa: BLE001 - reported to the next write()
            self.error = exc
            with self._cond:
                self._cond.notify_all()


class PtyTransport(TransportBase):
    """A pty pair made here: we read and write the master; give `path` to the peer."""

    def __init__(
        self,
        name: str = "pty",
        line_rate: float | None = LINE_RATE,
        bits_per_byte: int = BITS_PER_BYTE,
    ) -> None:
        self.name = name
        master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)  # binary-clean before the peer opens it (0x03 ≠ ^C)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave  # the slave stays open: no EIO before the peer
        self.path = os.ttyname(slave)
        self._closed = False
        self._writer = PacedWriter(self._write_all, byte_time_of(line_rate, bits_per_byte), name)

    def fileno(self) -> int | None:
        return self._master

    def send(self, data: bytes) -> None:
        self._writer.write(data)

    def recv(self, timeout: float | None = None) -> bytes:
        if self._closed:
            raise TransportClosed(f"{self.name} is closed")
        ready, _, _ = select.select([self._master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self._master, READ_SIZE)
        except BlockingIOError:
            return b""
        except OSError as exc:
            raise TransportClosed(f"{self.name}: {exc}") from exc

    def drain(self, timeout: float | None = None) -> bool:
        return self._writer.drain(timeout)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._writer.close()
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def _write_all(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._closed:
                raise TransportClosed("closed while writing")
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                select.select([], [self._master], [], 0.05)
                continue
            view = view[n:]


class SerialTransport(TransportBase):
    """Any pyserial URL or device path (the peer side of a `PtyTransport` is its `.path`)."""

    def __init__(
        self,
        url: str,
        name: str | None = None,
        line_rate: float | None = LINE_RATE,
        bits_per_byte: int = BITS_PER_BYTE,
        baudrate: int = 9600,
    ) -> None:
        self.name = name or url
        try:
            self._port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, do_not_open=True)
            if not url.startswith("rfc2217://"):  # pyserial's RFC 2217 client refuses one
                self._port.write_timeout = WRITE_TIMEOUT
            self._port.open()
        except (serial.SerialException, ValueError, OSError) as exc:
            raise TransportClosed(f"cannot open {url}: {exc}") from exc
        self._closed = False
        try:
            fd = self._port.fileno()
        except (AttributeError, NotImplementedError, OSError, serial.SerialException):
            fd = None
        self._fd: int | None = fd if isinstance(fd, int) else None
        self._writer = PacedWriter(
            self._write_all, byte_time_of(line_rate, bits_per_byte), self.name
        )

    def fileno(self) -> int | None:
        return self._fd

    def send(self, data: bytes) -> None:
        self._writer.write(data)

    def recv(self, timeout: float | None = None) -> bytes:
        if self._closed:
            raise TransportClosed(f"{self.name} is closed")
        try:
            if self._fd is not None:
                ready, _, _ = select.select([self._fd], [], [], timeout)
                if not ready:
                    return b""
                data = self._port.read(max(1, self._port.in_waiting))
                if not data:  # readable but empty: the far end hung up
                    raise TransportClosed(f"{self.name}: hung up")
                return bytes(data)
            return self._poll(timeout)
        except (serial.SerialException, OSError) as exc:  # a pty whose far end closed: EIO
            raise TransportClosed(f"{self.name}: {exc}") from exc

    def _poll(self, timeout: float | None) -> bytes:
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            waiting = self._port.in_waiting
            if waiting:
                return bytes(self._port.read(waiting))
            if end is not None and time.monotonic() >= end:
                return b""
            time.sleep(0.001)

    def drain(self, timeout: float | None = None) -> bool:
        return self._writer.drain(timeout)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._writer.close()
        self._port.close()

    def _write_all(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._closed:
                raise TransportClosed("closed while writing")
            try:
                n = self._port.write(view)
            except serial.SerialTimeoutException:
                continue
            view = view[n or 0 :]


def open_transport(
    endpoint: str,
    name: str | None = None,
    line_rate: float | None = LINE_RATE,
    bits_per_byte: int = BITS_PER_BYTE,
    profile: FrameProfile | None = None,
) -> PtyTransport | SerialTransport | MemorySerialTransport:
    """`pty` makes a pty pair (give `.path` to the peer); `virtual://LINK/END` is that end of a
    wire of the memory network on the running loop (a lab in one process: paced at the line rate
    in the loop's time; `profile` is the wire's framing); anything else is a pyserial URL/path."""
    if endpoint.startswith(VIRTUAL_SCHEME):
        net = network_of(asyncio.get_running_loop())
        if net is None:
            raise TransportClosed(
                f"{endpoint}: virtual wires exist only in a lab run in one process"
            )
        wire_profile = profile if profile is not None else get_profile("ktcs-type1")
        return net.open_serial(endpoint, wire_profile, byte_time_of(line_rate, bits_per_byte))
    if endpoint == "pty":
        return PtyTransport(name or "pty", line_rate, bits_per_byte)
    return SerialTransport(endpoint, name, line_rate, bits_per_byte)
