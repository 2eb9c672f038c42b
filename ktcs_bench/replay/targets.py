"""Where a replay sends its frames and hears the replies: a byte stream (a pty, a pyserial URL,
a TCP address) or a running tap (frames injected as if sent by one end). Each runs a reader
thread that puts the replies, framed, on a queue."""

from __future__ import annotations

import os
import queue
import socket
import threading
import time
from typing import Any

import serial

from ktcs_bench.capture import CaptureRecord, reverse_direction
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.recorder import Recorder
from ktcs_bench.tap.registry import tap_file
from ktcs_bench.transport.endpoints import parse_endpoint


class ReplayTarget:
    """Where frames go; replies arrive framed, as capture records, on `replies`."""

    def __init__(self) -> None:
        self.replies: queue.Queue[CaptureRecord] = queue.Queue()
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)

    def _start(self, fn: Any) -> None:
        self._thread = threading.Thread(target=fn, daemon=True)
        self._thread.start()


class StreamTarget(ReplayTarget):
    """A pty, a pyserial URL, or a TCP address: a byte stream both ways."""

    def __init__(self, spec: str, profile: FrameProfile, reply_dir: str, baud: int) -> None:
        super().__init__()
        self.spec = spec
        self._sock: socket.socket | None = None
        self._port: serial.Serial | None = None
        self._recorder = Recorder(profile)
        self._reply_dir = reply_dir
        if spec.startswith("tcp://"):
            ep = parse_endpoint(spec)
            try:
                self._sock = socket.create_connection((ep.host, ep.port), timeout=5)
            except OSError as exc:
                raise PeerError(f"cannot connect to {spec}: {exc}") from None
            self._sock.settimeout(0.05)
        else:
            try:
                self._port = serial.serial_for_url(spec, baudrate=baud, timeout=0.05)
            except (serial.SerialException, ValueError) as exc:
                raise PeerError(f"cannot open {spec}: {exc}") from None
        self._start(self._read)

    def send(self, data: bytes) -> None:
        try:
            if self._sock is not None:
                self._sock.sendall(data)
            elif self._port is not None:
                self._port.write(data)
                self._port.flush()
        except (OSError, serial.SerialException) as exc:
            raise PeerError(f"{self.spec}: {exc}") from None

    def _read(self) -> None:
        while not self._stop.is_set():
            data = b""
            try:
                if self._sock is not None:
                    data = self._sock.recv(65536)
                    if not data:
                        self.errors.append("the peer closed the connection")
                        break
                elif self._port is not None:
                    data = self._port.read(
                        max(1, self._port.in_waiting)
                    )  # returns at the first byte
            except TimeoutError:
                pass
            except (OSError, serial.SerialException) as exc:
                self.errors.append(str(exc))
                break
            now = time.time()
            for rec in self._recorder.feed(self._reply_dir, data, now) if data else []:
                self.replies.put(rec)
            for rec in self._recorder.handle_timer(now):
                self.replies.put(rec)
        for rec in self._recorder.flush():
            self.replies.put(rec)

    def close(self) -> None:
        super().close()
        if self._sock is not None:
            self._sock.close()
        if self._port is not None:
            self._port.close()


class TapTarget(ReplayTarget):
    """A running tap: frames are injected with `send DIR HEX`; replies come from `subscribe`."""

    def __init__(self, spec: str, send_dir: str | None) -> None:
        super().__init__()
        self._ctl = TapClient(spec)
        self._sub = TapClient(spec)
        events = self._sub.subscribe(timeout=None)
        self.header = next(events)
        a, b = self.header["names"]
        dirs = (f"{a}>{b}", f"{b}>{a}")
        self.send_dir = send_dir if send_dir in dirs else dirs[0]
        self.reply_dir = reverse_direction(self.send_dir)
        self._events = events
        self._start(self._read)

    def send(self, data: bytes) -> None:
        self._ctl.command(f"send {self.send_dir} {data.hex()}")

    def _read(self) -> None:
        try:
            for ev in self._events:
                if ev.get("direction") == self.reply_dir and "hex" in ev:
                    self.replies.put(
                        CaptureRecord(ev.get("time"), self.reply_dir, bytes.fromhex(ev["hex"]))
                    )
        except (PeerError, OSError, ValueError) as exc:
            if not self._stop.is_set():
                self.errors.append(str(exc))

    def close(self) -> None:
        self._stop.set()
        self._sub.close()  # ends the subscription read
        self._ctl.close()
        super().close()


def is_tap(spec: str) -> bool:
    """`spec` names a running tap (tap://HOST:PORT, or a tap's name), not a stream."""
    if spec.startswith("tap://") or spec.startswith("tap:"):
        return True
    if "://" in spec or spec.startswith("/") or os.path.exists(spec):
        return False
    try:
        return tap_file(spec).is_file()
    except UsageError:
        return False
