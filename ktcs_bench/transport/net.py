"""The one seam between the devices and the network: TCP live, the memory network in process.

`open_connection` and `start_server` use the `transport.memory` network attached to the running
loop when there is one (the whole lab in one process), else asyncio's real ones. Every
device-side TCP use goes through here (the Type II client and server, the JSON-lines control ports
and the rails), so the same code runs on both. `real=True` asks for a real socket whatever the
loop (a lab in one process still serves its console and control ports to people). TLS is
live-only: asked for on the memory network it is a UsageError.
"""

from __future__ import annotations

import asyncio
import ssl as ssl_module
from collections.abc import Sequence
from typing import Any, Protocol

from ktcs_bench.errors import UsageError
from ktcs_bench.transport import memory

LIMIT = 1 << 16  # asyncio's default line limit


class SocketLike(Protocol):
    def getsockname(self) -> Any: ...


class Server(Protocol):
    """What the bench uses of a server: asyncio's, or the memory network's."""

    @property
    def sockets(self) -> Sequence[SocketLike]: ...

    def close(self) -> None: ...

    async def wait_closed(self) -> None: ...


def in_memory() -> bool:
    """True when the running loop carries a memory network (the lab runs in one process)."""
    return memory.network_of(asyncio.get_running_loop()) is not None


async def open_connection(
    host: str,
    port: int,
    *,
    limit: int = LIMIT,
    ssl: ssl_module.SSLContext | None = None,
    server_hostname: str | None = None,
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    net = memory.network_of(asyncio.get_running_loop())
    if net is None:
        return await asyncio.open_connection(
            host, port, limit=limit, ssl=ssl, server_hostname=server_hostname
        )
    if ssl is not None:
        raise UsageError("Type II over TLS runs in a live lab only (lab up), not in one process")
    return await net.open_connection(host, port, limit=limit)


async def start_server(
    callback: memory.ClientConnected,
    host: str,
    port: int,
    *,
    limit: int = LIMIT,
    real: bool = False,
    **kwargs: Any,
) -> Server:
    """A server at host:port (port 0: any free one); `kwargs` go to asyncio's (e.g.
    `reuse_address`). `real`: a real socket even when the loop has a memory network."""
    net = memory.network_of(asyncio.get_running_loop())
    if net is None or real:
        server: Server = await asyncio.start_server(callback, host, port, limit=limit, **kwargs)
        return server
    return await net.start_server(callback, host, port, limit=limit)


def server_address(server: Server) -> tuple[str, int]:
    """(host, port) a server listens on (its first socket)."""
    name = server.sockets[0].getsockname()
    return str(name[0]), int(name[1])
