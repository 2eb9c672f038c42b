"""A serial line of this host served over the network as RFC 2217 (Telnet COM-PORT-OPTION), so a
tap on another host opens it with pyserial's `rfc2217://HOST:PORT` -- the way real labs reach a
device behind a serial server (ser2net). The protocol is pyserial's own server side
(`serial.rfc2217.PortManager`); this module only carries bytes between it, a socket and the line.

The line is a device's pty (its Type I end, `--link ROLE=pty`): `path()` says where it is now, so
a device that restarts on a new pty is found again. A pty has no modem lines: the client's
DTR/RTS and break requests are answered and ignored (`PtyLine`). One client at a time: a new
connection replaces the old one (a client that lost its network connects again while the old
socket still looks open here). Bytes from the line while no client is connected are lost, as on
a line with nothing on it.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
from collections.abc import Callable
from typing import Any, TypedDict, cast

import serial
import serial.rfc2217

log = logging.getLogger("ktcs_bench.rfc2217")

REOPEN = 0.5  # s between attempts to open the line when it is not there (the device restarting)
READ_TIMEOUT = 0.2  # s a read of the line waits, so the server notices stop and a new path
ACCEPT_TIMEOUT = 0.5  # s, how long an accept waits before it checks for stop
WRITE_TIMEOUT = 2.0  # s a write to the line may block (a device that stopped reading)
SEND_TIMEOUT = 5.0  # s a send to the client may block before the client is dropped


class PtyLine(serial.Serial):
    """A pty as pyserial's Serial with no modem lines: setting DTR, RTS or break does nothing,
    reading CTS, DSR, RI or CD gives False, and flushing a closed line is a no-op (a pty cannot
    do these; an RFC 2217 client asks for them all the same)."""

    def _update_dtr_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return False

    @property
    def dsr(self) -> bool:
        return False

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return False

    def reset_input_buffer(self) -> None:
        if self.is_open:
            super().reset_input_buffer()

    def reset_output_buffer(self) -> None:
        if self.is_open:
            super().reset_output_buffer()


class Rfc2217Status(TypedDict):
    """What `Rfc2217Server.status` reports."""

    listen: str
    path: str | None
    open: bool
    client: str | None
    connections: int


class _Client:
    """One connected client: its socket (written under a lock: the line's reader and the
    PortManager's answers both write) and its protocol state."""

    def __init__(self, sock: socket.socket, peer: str, line: PtyLine) -> None:
        self.sock, self.peer = sock, peer
        self._lock = threading.Lock()
        # the manager writes to any object with `write` (its stubs say a Serial): sends its
        # negotiation at once
        self.manager = serial.rfc2217.PortManager(cast(Any, line), cast(Any, self))

    def write(self, data: bytes) -> None:
        with self._lock:
            self.sock.sendall(data)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self.sock.close()


def _tune(sock: socket.socket) -> None:
    """A client's socket: no Nagle delay (a Type I frame is small and timed); a send that
    cannot go on for SEND_TIMEOUT fails (a client whose network is cut is dropped, and connects
    again when it is back); keepalive probes find a client that vanished while nothing flowed."""
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.settimeout(SEND_TIMEOUT)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for option, value in (("TCP_KEEPIDLE", 5), ("TCP_KEEPINTVL", 2), ("TCP_KEEPCNT", 3)):
        if hasattr(socket, option):
            sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)


class Rfc2217Server:
    """Serve the serial line at `path()` over RFC 2217 on `listen` (HOST, PORT).

    server = Rfc2217Server(("10.0.0.2", 7703), lambda: "/dev/pts/5", name="iv2022")
    server.start()   # binds (an OSError if the port is taken), then serves in threads
    server.stop()
    """

    def __init__(
        self, listen: tuple[str, int], path: Callable[[], str | None], name: str = "rfc2217"
    ) -> None:
        self.listen, self.path, self.name = listen, path, name
        self.line = PtyLine(timeout=READ_TIMEOUT, write_timeout=WRITE_TIMEOUT)
        self.client: _Client | None = None
        self.connections = 0
        self._opened: str | None = None  # the path the line is open on
        self._lock = threading.Lock()  # the line's open, close and writes
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._threads: list[threading.Thread] = []

    def start(self) -> None:
        sock = socket.socket(socket.AF_INET6 if ":" in self.listen[0] else socket.AF_INET)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(self.listen)
            sock.listen(4)
        except OSError:
            sock.close()
            raise
        sock.settimeout(ACCEPT_TIMEOUT)
        self._sock = sock
        self.listen = sock.getsockname()[:2]  # the port bound, when 0 asked for any free one
        for target in (self._accept_main, self._line_main):
            thread = threading.Thread(target=target, name=f"{self.name}-{target.__name__}",
                                      daemon=True)  # fmt: skip
            thread.start()
            self._threads.append(thread)

    def stop(self) -> None:
        self._stop.set()
        if self._sock is not None:
            self._sock.close()
        client, self.client = self.client, None
        if client is not None:
            client.close()
        for thread in self._threads:
            thread.join(5.0)
        with self._lock:
            self.line.close()

    def status(self) -> Rfc2217Status:
        client = self.client
        return {"listen": f"{self.listen[0]}:{self.listen[1]}", "path": self._opened,
                "open": self.line.is_open, "client": client.peer if client else None,
                "connections": self.connections}  # fmt: skip

    # -- the network side ---------------------------------------------------------------------
    def _accept_main(self) -> None:
        assert self._sock is not None
        while not self._stop.is_set():
            try:
                sock, addr = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return  # closed by stop
            _tune(sock)
            old = self.client
            try:
                client = _Client(sock, f"{addr[0]}:{addr[1]}", self.line)
            except OSError:
                sock.close()
                continue
            self.client, self.connections = client, self.connections + 1
            if old is not None:
                old.close()  # replaced: its reader ends on the closed socket
            log.info("%s: client %s", self.name, client.peer)
            threading.Thread(target=self._client_main, args=(client,), daemon=True,
                             name=f"{self.name}-client").start()  # fmt: skip

    def _client_main(self, client: _Client) -> None:
        """What the client sends: telnet and RFC 2217 commands (the manager acts on them) and
        the bytes for the line."""
        while not self._stop.is_set():
            try:
                data = client.sock.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                break
            if not data:
                break
            try:
                with self._lock:
                    payload = b"".join(client.manager.filter(data))
                    if payload and self.line.is_open:
                        self.line.write(payload)
            except (serial.SerialException, OSError, ValueError) as exc:
                log.warning("%s: %s", self.name, exc)  # the line went away: the reader reopens
        if self.client is client:
            self.client = None
        client.close()

    # -- the line side ------------------------------------------------------------------------
    def _line_main(self) -> None:
        """Keep the line open on its current path and send what it reads to the client."""
        while not self._stop.is_set():
            path = self.path()
            if self.line.is_open and path != self._opened:
                self._close_line()  # the device restarted on another pty
            if not self.line.is_open:
                if path is None or not self._open_line(path):
                    self._stop.wait(REOPEN)
                    continue
            try:
                data = self.line.read(self.line.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError):
                self._close_line()
                continue
            client = self.client
            if data and client is not None:
                try:
                    client.write(b"".join(client.manager.escape(data)))
                except OSError:
                    if self.client is client:
                        self.client = None
                    client.close()

    def _open_line(self, path: str) -> bool:
        with self._lock:
            try:
                self.line.port = path
                self.line.open()
            except (serial.SerialException, OSError) as exc:
                log.debug("%s: cannot open %s: %s", self.name, path, exc)
                return False
            self._opened = path
            return True

    def _close_line(self) -> None:
        with self._lock:
            with contextlib.suppress(serial.SerialException, OSError):
                self.line.close()
            self._opened = None
