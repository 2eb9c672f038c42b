"""JSON lines over asyncio streams: the bench's own control and field-bus framing.

Not a kTCS protocol -- it carries what the real lab moves by wire and rail (occupancy, codes under
the antenna, train positions) and operator/control commands. A line is one JSON object; lines are
bounded (`LIMIT`), a bad line gets `{"error": ...}` back and never ends the connection.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from typing import Any

from ktcs_bench.transport.tcp import open_tcp

LIMIT = 1 << 20  # one line at most 1 MiB: a full status of a large station is a few kB

Handler = Callable[[dict[str, Any], "Peer"], Awaitable[dict[str, Any] | None]]


class Peer:
    """One connected JSON-lines peer: send objects, remember what it said it is."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.info: dict[str, Any] = {}
        peer = writer.get_extra_info("peername")
        self.address = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)

    def send(self, obj: dict[str, Any]) -> None:
        if not self.writer.is_closing():
            self.writer.write(json.dumps(obj, separators=(",", ":")).encode() + b"\n")

    async def read(self) -> dict[str, Any] | None:
        """The next object; None at end of stream. Bad lines raise ValueError."""
        try:
            line = await self.reader.readline()
        except (asyncio.LimitOverrunError, ValueError):
            raise ValueError("line too long") from None
        if not line:
            return None
        obj = json.loads(line)
        if not isinstance(obj, dict):
            raise ValueError("a line must hold a JSON object")
        return obj

    def close(self) -> None:
        self.writer.close()


async def serve(
    host: str, port: int, handler: Handler, on_close: Callable[[Peer], None] | None = None
) -> asyncio.Server:
    """A JSON-lines server: each object goes to `handler`, whose answer (if any) is sent back."""

    async def client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = Peer(reader, writer)
        try:
            while True:
                try:
                    obj = await peer.read()
                except ValueError as exc:
                    peer.send({"error": f"bad line: {exc}"})
                    continue
                if obj is None:
                    break
                answer = await handler(obj, peer)
                if answer is not None:
                    peer.send(answer)
                await writer.drain()
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        except asyncio.CancelledError:
            # the process is shutting down and asyncio.run cancels what is left: the connection
            # ends here, quietly (Python 3.11's stream server logs a cancelled one as an error
            # with a CancelledError traceback)
            pass
        finally:
            if on_close is not None:
                on_close(peer)
            writer.close()

    return await asyncio.start_server(client, host, port, limit=LIMIT)


async def connect(host: str, port: int) -> Peer:
    reader, writer = await open_tcp(host, port, limit=LIMIT)
    return Peer(reader, writer)


async def request(
    host: str, port: int, obj: dict[str, Any], timeout: float = 10.0
) -> dict[str, Any]:
    """One command to a control port, one answer back."""
    async with asyncio.timeout(timeout):
        peer = await connect(host, port)
        try:
            peer.send(obj)
            answer = await peer.read()
        finally:
            peer.close()
    if answer is None:
        raise ConnectionError(f"{host}:{port} closed without answering")
    return answer
