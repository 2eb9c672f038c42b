"""An in-memory network on one asyncio loop: the whole lab's TCP streams and serial wires in one
process (SPEC §11, `lab simulate`).

`MemoryNetwork` is attached to a running loop (`attach(loop)`); while it is, `transport.net`'s
`open_connection` / `start_server` use it instead of the operating system's sockets, so the same
device code runs on TCP live and on memory streams in process. A stream is a pair of
`MemoryTransport`s (an `asyncio.Transport`) under asyncio's own StreamReader/StreamWriter: bytes
written reach the peer's protocol at the next turn of the loop (`call_soon`, in order); `close`
delivers what was written, then end of file; nothing listening is a ConnectionRefusedError; a
reader that stops reading pauses delivery (flow control), as TCP does.

Serial wires (Type I) are `SerialEnd`s named `LINK/END` (the endpoint `virtual://LINK/END`):
`open_serial` gives a device a `MemorySerialTransport`, a push-style transport whose sends are
paced at the line rate as the virtual wire paces it (`transport.virtual.VirtualWire`: a piece of
bytes arrives when its last bit would have) on one loop timer at a time; what arrives goes to
whatever joins the two ends -- a tap (`tap.wire.WireTap`) or a plain join. No thread, no file
descriptor.

Who owns what: every server and connection is marked with the owner in `OWNER` (a context
variable the in-process lab sets per device) when it is made, so `drop(owner)` can do what the
death of a device's process does live: its servers stop listening, its connections are reset and
the tasks serving them end.
"""

from __future__ import annotations

import asyncio
import contextvars
import errno
import weakref
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError
from ktcs_bench.transport.base import TransportBase, TransportClosed
from ktcs_bench.transport.virtual import Flight, put_in_pieces, take_arrived

OWNER: contextvars.ContextVar[str] = contextvars.ContextVar("ktcs_memory_owner", default="")
"""Who makes a server or a connection now (the in-process lab sets a device's name)."""

FIRST_PORT = 40000  # ports handed out for port 0 and for clients' own ends
VIRTUAL_SCHEME = "virtual://"

ClientConnected = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None] | None]

_networks: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, MemoryNetwork] = (
    weakref.WeakKeyDictionary()
)


def attach(loop: asyncio.AbstractEventLoop) -> MemoryNetwork:
    """The memory network of `loop`, made on first use: from now on `transport.net` uses it."""
    net = _networks.get(loop)
    if net is None:
        net = _networks[loop] = MemoryNetwork(loop)
    return net


def detach(loop: asyncio.AbstractEventLoop) -> None:
    _networks.pop(loop, None)


def network_of(loop: asyncio.AbstractEventLoop) -> MemoryNetwork | None:
    return _networks.get(loop)


class MemoryTransport(asyncio.Transport):
    """One end of an in-memory stream."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        protocol: asyncio.Protocol,
        local: tuple[str, int],
        remote: tuple[str, int],
        owner: str,
    ) -> None:
        super().__init__({"sockname": local, "peername": remote})
        self._loop = loop
        self._protocol = protocol
        self.owner = owner
        self.peer: MemoryTransport | None = None
        self._closing = False  # this end closed (no more writes)
        self._lost = False  # the protocol was told the connection is gone
        self._paused = False
        self._held: deque[bytes | None] = deque()  # while paused; None = end of file

    # -- asyncio.Transport -----------------------------------------------------------------------
    def get_protocol(self) -> asyncio.BaseProtocol:
        return self._protocol

    def set_protocol(self, protocol: asyncio.BaseProtocol) -> None:
        assert isinstance(protocol, asyncio.Protocol)
        self._protocol = protocol

    def is_closing(self) -> bool:
        return self._closing

    def write(self, data: bytes | bytearray | memoryview) -> None:
        if self._closing or not data:
            return
        peer = self.peer
        if peer is not None:
            self._loop.call_soon(peer._arrive, bytes(data))

    def writelines(self, list_of_data: Any) -> None:
        for data in list_of_data:
            self.write(data)

    def can_write_eof(self) -> bool:
        return True

    def write_eof(self) -> None:
        if self.peer is not None and not self._closing:
            self._loop.call_soon(self.peer._arrive, None)

    def get_write_buffer_size(self) -> int:
        return 0

    def get_write_buffer_limits(self) -> tuple[int, int]:
        return (0, 0)

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        pass

    def pause_reading(self) -> None:
        self._paused = True

    def resume_reading(self) -> None:
        if self._paused:
            self._paused = False
            self._loop.call_soon(self._release)

    def is_reading(self) -> bool:
        return not self._paused

    def close(self) -> None:
        """What was written is delivered, then the peer reads end of file (FIN)."""
        if self._closing:
            return
        self._closing = True
        if self.peer is not None:
            self._loop.call_soon(self.peer._arrive, None)
        self._loop.call_soon(self._connection_lost, None)

    def abort(self) -> None:
        """The connection is reset: the peer is told at once, nothing more is delivered."""
        if self._lost:
            return
        self._closing = True
        self._held.clear()
        peer = self.peer
        if peer is not None and not peer._lost:
            peer._closing = True
            peer._held.clear()
            self._loop.call_soon(peer._connection_lost, ConnectionResetError("connection reset"))
        self._loop.call_soon(self._connection_lost, None)

    # -- delivery --------------------------------------------------------------------------------
    def _arrive(self, data: bytes | None) -> None:
        if self._lost:
            return
        if self._paused or self._held:
            self._held.append(data)
            return
        self._give(data)

    def _release(self) -> None:
        while self._held and not self._paused and not self._lost:
            self._give(self._held.popleft())

    def _give(self, data: bytes | None) -> None:
        if data is None:
            keep_open = self._protocol.eof_received()
            if not keep_open:
                self.close()
            return
        self._protocol.data_received(data)

    def _connection_lost(self, exc: Exception | None) -> None:
        if self._lost:
            return
        self._closing = True
        self._release()  # what had arrived before the end is still read
        self._lost = True
        self._protocol.connection_lost(exc)


class _Socket:
    """What a server's `sockets` show: the address it listens on."""

    def __init__(self, address: tuple[str, int]) -> None:
        self._address = address

    def getsockname(self) -> tuple[str, int]:
        return self._address


class MemoryServer:
    """A listening address on the memory network (the part of `asyncio.Server` the bench uses)."""

    def __init__(
        self,
        net: MemoryNetwork,
        callback: ClientConnected,
        address: tuple[str, int],
        limit: int,
        owner: str,
    ) -> None:
        self.net, self.callback, self.address, self.limit = net, callback, address, limit
        self.owner = owner
        self.context = contextvars.copy_context()
        self.sockets = [_Socket(address)]
        self._serving = True
        self._closed = asyncio.Event()

    def is_serving(self) -> bool:
        return self._serving

    def close(self) -> None:
        if self._serving:
            self._serving = False
            self.net._unlisten(self)
            self._closed.set()

    async def wait_closed(self) -> None:
        await self._closed.wait()


class MemoryNetwork:
    """The streams and serial wires of one loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._servers: dict[tuple[str, int], MemoryServer] = {}
        self._next_port = FIRST_PORT
        self._connections: list[MemoryTransport] = []
        self._handlers: dict[str, set[asyncio.Task[Any]]] = {}
        self.serial: dict[str, SerialEnd] = {}
        self.token: str | None = None  # the token of the lab on this network (its ports')

    def _port(self) -> int:
        while True:
            self._next_port += 1
            if not any(port == self._next_port for _, port in self._servers):
                return self._next_port

    # -- streams ---------------------------------------------------------------------------------
    async def start_server(
        self, callback: ClientConnected, host: str, port: int, *, limit: int
    ) -> MemoryServer:
        address = (host, port or self._port())
        if address in self._servers:
            raise OSError(errno.EADDRINUSE, f"address already in use: {host}:{address[1]}")
        server = self._servers[address] = MemoryServer(self, callback, address, limit, OWNER.get())
        return server

    def _unlisten(self, server: MemoryServer) -> None:
        if self._servers.get(server.address) is server:
            del self._servers[server.address]

    async def open_connection(
        self, host: str, port: int, *, limit: int
    ) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        server = self._servers.get((host, port))
        await asyncio.sleep(0)  # a connection takes a turn of the loop, as a handshake does
        if server is None or not server.is_serving():
            raise ConnectionRefusedError(errno.ECONNREFUSED, f"nothing listens on {host}:{port}")
        loop = self.loop
        mine = ("127.0.0.1", self._port())
        reader = asyncio.StreamReader(limit=limit, loop=loop)
        protocol = asyncio.StreamReaderProtocol(reader, loop=loop)
        client = MemoryTransport(loop, protocol, mine, server.address, OWNER.get())
        s_reader = asyncio.StreamReader(limit=server.limit, loop=loop)
        s_protocol = asyncio.StreamReaderProtocol(s_reader, loop=loop)
        end = MemoryTransport(loop, s_protocol, server.address, mine, server.owner)
        client.peer, end.peer = end, client
        self._connections += [client, end]
        self._connections = [t for t in self._connections if not t._lost]
        s_protocol.connection_made(end)
        protocol.connection_made(client)
        s_writer = asyncio.StreamWriter(end, s_protocol, s_reader, loop)
        result = server.callback(s_reader, s_writer)
        if asyncio.iscoroutine(result):
            task = loop.create_task(result, context=server.context)
            handlers = self._handlers.setdefault(server.owner, set())
            handlers.add(task)
            task.add_done_callback(handlers.discard)
        return reader, asyncio.StreamWriter(client, protocol, reader, loop)

    def drop(self, owner: str) -> None:
        """What the death of `owner`'s process does: its servers stop listening, its connections
        are reset (the peers read a reset) and the tasks serving them are cancelled."""
        for server in [s for s in self._servers.values() if s.owner == owner]:
            server.close()
        for t in self._connections:
            if t.owner == owner:
                t.abort()
        for task in sorted(self._handlers.pop(owner, set()), key=lambda t: t.get_name()):
            task.cancel()

    # -- serial wires ----------------------------------------------------------------------------
    def serial_end(self, name: str) -> SerialEnd:
        """The end `LINK/END` of a serial wire (made on first use)."""
        end = self.serial.get(name)
        if end is None:
            end = self.serial[name] = SerialEnd(name)
        return end

    def join_serial(self, a: str, b: str) -> None:
        """Join ends `a` and `b` straight (a Type I link with no tap)."""
        ea, eb = self.serial_end(a), self.serial_end(b)
        ea.join = lambda data, now: eb.deliver(data)
        eb.join = lambda data, now: ea.deliver(data)

    def open_serial(
        self, endpoint: str, profile: FrameProfile, byte_time: float
    ) -> MemorySerialTransport:
        """A device's side of `virtual://LINK/END`, paced at `byte_time` a byte."""
        name = endpoint.removeprefix(VIRTUAL_SCHEME)
        end = self.serial.get(name)
        if end is None or end.join is None:
            known = ", ".join(sorted(self.serial)) or "none"
            raise TransportClosed(f"no virtual wire {endpoint} in this lab (ends: {known})")
        return MemorySerialTransport(end, profile, byte_time)


class SerialEnd:
    """One end of a serial wire: the device's transport on one side, the join (a tap, or the
    other end) on the other. `join(data, now)` takes what the device's line delivered; `deliver`
    hands bytes to the device -- straight to what its transport was attached to (lost when no
    device holds the end, as on a line whose far end is unplugged)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.join: Callable[[bytes, float], None] | None = None
        self.transport: MemorySerialTransport | None = None
        self.deliver: Callable[[bytes], None] = _unplugged


def _unplugged(data: bytes) -> None:
    """Bytes for an end no device holds (or whose device attached nothing yet): lost."""


class MemorySerialTransport(TransportBase):
    """A device's end of a virtual serial wire: push style (`attach(on_data, on_closed)`), no fd.

    Sends leave at the line rate, paced as `VirtualWire` paces them (the same arithmetic, the
    same instants): a send's pieces of `PIECE` bytes queue, and one loop timer at a time stands at
    the earliest, re-armed after each arrival has been handed on -- the loop's timers made and
    ordered exactly as a `LoopTimer` on a `VirtualWire` would make them, without that core asked
    again after every piece (a device's end has no faults: a link's faults are its tap's). Every
    byte of every Type I link of a lab comes this way."""

    def __init__(self, end: SerialEnd, profile: FrameProfile, byte_time: float) -> None:
        self.name = end.name
        self.end = end
        self.byte_time = byte_time
        self._free_at = 0.0  # when the line has sent everything handed to it
        self._flight: Flight = deque()
        self._handle: asyncio.TimerHandle | None = None  # at the first piece in flight
        self._loop: asyncio.AbstractEventLoop | None = None
        self._on_data: Callable[[bytes], None] | None = None
        self._on_closed: Callable[[BaseException], None] | None = None
        self._closed = False
        if end.transport is not None:  # a new device on the end: the old one is gone
            end.transport.close()
        end.transport = self

    def attach(
        self, on_data: Callable[[bytes], None], on_closed: Callable[[BaseException], None]
    ) -> None:
        self._on_data, self._on_closed = on_data, on_closed
        if not self._closed and self.end.transport is self:
            self.end.deliver = on_data  # what arrives at this end, without a call between

    def _arrive(self) -> None:
        """The first piece in flight is due: it (and any due with it) goes to the join, then the
        timer stands at the next."""
        self._handle = None
        if self._closed:
            return
        flight = self._flight
        loop = self._loop
        assert loop is not None
        now = loop.time()
        due = flight[0][0]
        if now < due:  # the loop's clock a hair short of the deadline it ran the timer for
            now = due
        out = take_arrived(flight, now)
        if self.end.join is not None:
            self.end.join(out, now)
        if flight and self._handle is None and not self._closed:  # (a send it caused armed it)
            self._handle = loop.call_at(flight[0][0], self._arrive)

    # -- Transport -------------------------------------------------------------------------------
    def send(self, data: bytes) -> None:
        if self._closed:
            raise TransportClosed(f"{self.name} is closed")
        loop = self._loop
        if loop is None:
            loop = self._loop = asyncio.get_running_loop()
        start = loop.time()
        if start < self._free_at:
            start = self._free_at
        flight = self._flight
        self._free_at = put_in_pieces(flight, bytes(data), start, self.byte_time)
        if self._handle is None and flight:
            self._handle = loop.call_at(flight[0][0], self._arrive)

    def recv(self, timeout: float | None = None) -> bytes:
        raise UsageError("a virtual serial end pushes what arrives (attach), it is not polled")

    def fileno(self) -> int | None:
        return None

    def drain(self, timeout: float | None = None) -> bool:
        return not self._flight

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self.end.transport is self:
            self.end.transport = None
            self.end.deliver = _unplugged
