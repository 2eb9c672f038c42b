"""The TCP adapter: a tap between TCP ends, for a Type II link.

End a connects to the tap's listening address, and for each connection the tap connects on to the
target (end b). One connection at a time: a new one replaces the old. `cut` with no direction
closes both sides and refuses connections until `restore`. The capture writers learn the real
addresses of both ends of each connection (pcapng shows them).
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass
from typing import Any

from ktcs_bench.tap.registry import TapEnds
from ktcs_bench.tap.runner import Tap, TapStatus
from ktcs_bench.transport import net
from ktcs_bench.transport.tcp import open_tcp

CONNECT_TIMEOUT = 5.0


class TcpStatus(TapStatus):
    """A TCP tap's status: a connection carries the link, and how many have."""

    connected: bool
    connections: int


@dataclass
class _Conn:
    a_reader: asyncio.StreamReader
    a_writer: asyncio.StreamWriter
    b_reader: asyncio.StreamReader
    b_writer: asyncio.StreamWriter
    peer: tuple[str, int]


class TcpTap(Tap):
    """A tap between TCP ends: end a connects to `listen`, the tap connects on to `target` (end b).

        with TcpTap(("127.0.0.1", 0), ("127.0.0.1", 5020), names=("ixl", "ctc")) as tap:
            ixl connects to tap.listen_address
    One connection at a time: a new connection replaces the old one. `cut()` closes both sides
    and refuses connections until `restore()`.
    """

    kind = "tcp"

    def __init__(self, listen: tuple[str, int], target: tuple[str, int], **kwargs: Any) -> None:
        kwargs.setdefault("profile", "ktcs-type2")
        super().__init__(**kwargs)
        self.listen = listen
        self.target = target
        self.listen_address: tuple[str, int] | None = None
        self._listener: net.Server | None = None
        self._conn: _Conn | None = None
        self.connections = 0

    def _ends_info(self) -> TapEnds:
        addr = self.listen_address or self.listen
        return {"listen": list(addr), "target": list(self.target)}

    @property
    def connected(self) -> bool:
        return self._conn is not None

    async def _open_ends(self) -> None:
        self._listener = await net.start_server(self._accept, *self.listen)
        self.listen_address = net.server_address(self._listener)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername") or ("?", 0)
        if self.core.cut_all:
            writer.close()
            self._apply(self.core.note(self._now(), {"event": "refused", "peer": list(peer[:2])}))
            return
        try:
            b_reader, b_writer = await asyncio.wait_for(open_tcp(*self.target), CONNECT_TIMEOUT)
        except (OSError, TimeoutError) as exc:
            writer.close()
            self._apply(self.core.note(self._now(), {"event": "target-failed", "error": str(exc)}))
            return
        if self._conn is not None:
            self._drop("replaced by a new connection")
        conn = _Conn(reader, writer, b_reader, b_writer, (str(peer[0]), int(peer[1])))
        # what the recorder still holds of the old connection is written with its addresses
        self._apply(self.core.connected(self._now(), conn.peer))
        self._conn = conn
        self.connections += 1
        a, b = self.names
        target = b_writer.get_extra_info("peername") or self.target  # the address, not a name
        for w in self._writers:
            w.set_endpoint(a, *conn.peer)
            w.set_endpoint(b, str(target[0]), int(target[1]))
        self._spawn(self._read(conn, reader, self.directions[0]))
        self._spawn(self._read(conn, b_reader, self.directions[1]))

    async def _read(self, conn: _Conn, reader: asyncio.StreamReader, direction: str) -> None:
        try:
            while True:
                data = await reader.read(65536)
                if not data or conn is not self._conn:
                    break
                self._on_data(direction, data)
        except (ConnectionError, OSError):
            pass
        finally:
            if conn is self._conn:
                self._drop(f"{direction.split('>')[0]} closed")

    def _deliver(self, direction: str, data: bytes) -> None:
        conn = self._conn
        if conn is None:
            return
        w = conn.b_writer if direction == self.directions[0] else conn.a_writer
        if not w.is_closing():
            w.write(data)

    def _drop(self, reason: str) -> None:
        conn, self._conn = self._conn, None
        if conn is None:
            return
        for w in (conn.a_writer, conn.b_writer):
            with contextlib.suppress(Exception):
                w.close()
        self._apply(self.core.disconnected(self._now(), reason))

    def _link_cut(self) -> None:
        self._drop("cut")

    def _status(self) -> TcpStatus:
        return {**super()._status(), "connected": self.connected,
                "connections": self.connections}  # fmt: skip

    async def _close_ends(self) -> None:
        self._drop("tap stopped")
        if self._listener is not None:
            self._listener.close()
