"""JSON lines over asyncio streams: the bench's own control and field-bus framing.

Not a kTCS protocol -- it carries what the real lab moves by wire and rail (occupancy, codes under
the antenna, train positions) and operator/control commands: every device's control port and every
tap's speak it. A line is one JSON object; lines are bounded (`LIMIT`), a bad line gets
`{"error": ...}` back and never ends the connection.

Every server obeys only who holds its token (`runtime`): a connection is admitted by an object
carrying `"token": TOKEN` (the first, or any later one), and until then every object gets
`{"ok": false, "refused": true, "error": ...}` back and is not acted on. `request` presents the
token of the address it talks to, and raises PeerError on a refusal.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Literal, TypedDict

from ktcs_bench.errors import PeerError
from ktcs_bench.messages import JsonObject, Message, encode
from ktcs_bench.runtime import client_token, token_matches
from ktcs_bench.transport import memory, net
from ktcs_bench.transport.tcp import open_tcp

log = logging.getLogger("ktcs_bench.control")

LIMIT = 1 << 20  # one line at most 1 MiB: a full status of a large station is a few kB

Handler = Callable[[JsonObject, "Peer"], Awaitable[Mapping[str, object] | None]]
"""Takes each object an admitted peer sends (any JSON object: the handler checks it); its answer, if
any, is sent back."""


class Peer:
    """One connected JSON-lines peer: send objects, remember what it said it is."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.info: JsonObject = {}  # what it said it is (its hello)
        peer = writer.get_extra_info("peername")
        self.address = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)

    def send(self, obj: Mapping[str, object]) -> None:
        if not self.writer.is_closing():
            self.writer.write(json.dumps(obj, separators=(",", ":")).encode() + b"\n")

    async def read(self) -> JsonObject | None:
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


class Refusal(TypedDict):
    """What a port answers who does not present its lab's token."""

    ok: Literal[False]
    refused: Literal[True]
    error: str


def refusal(why: str) -> Refusal:
    return {"ok": False, "refused": True, "error": f"refused: {why}. {WHO_MAY}"}


WHO_MAY = (
    "This port obeys only who presents its lab's token (a file only the lab's owner can read; "
    "see the README, 'Who may operate a lab')"
)


async def serve(
    host: str,
    port: int,
    handler: Handler,
    on_close: Callable[[Peer], None] | None = None,
    *,
    token: str,
    real: bool = False,
) -> net.Server:
    """A JSON-lines server: each object of an admitted connection (see the module docstring) goes
    to `handler`, whose answer (if any) is sent back. `real`: on a real socket even in a lab run
    in one process (`transport.net`)."""

    async def client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = Peer(reader, writer)
        admitted = False
        try:
            while True:
                try:
                    obj = await peer.read()
                except ValueError as exc:
                    peer.send({"error": f"bad line: {exc}"})
                    continue
                if obj is None:
                    break
                if "token" in obj:
                    admitted = token_matches(obj.pop("token"), token)
                    if not admitted:
                        log.warning("%s:%s refused %s: wrong token", host, port, peer.address)
                        peer.send(refusal("wrong token"))
                        continue
                    if not obj:
                        peer.send({"ok": True})
                        continue
                if not admitted:
                    log.warning("%s:%s refused %s: no token", host, port, peer.address)
                    peer.send(refusal("no token"))
                    continue
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

    return await net.start_server(client, host, port, limit=LIMIT, real=real)


async def connect(host: str, port: int) -> Peer:
    reader, writer = await open_tcp(host, port, limit=LIMIT)
    return Peer(reader, writer)


async def request(
    host: str,
    port: int,
    obj: Message | Mapping[str, object],
    timeout: float = 10.0,
    token: str | None = None,
) -> dict[str, Any]:
    """One command (a message, `ktcs_bench.messages`, or its JSON object) to a control port, one
    answer back. The token presented is `token`, else the one `runtime.client_token` finds for the
    address (on a lab's memory network, the lab's); a refusal is a PeerError."""
    sent = encode(obj) if isinstance(obj, Message) else dict(obj)
    if token is None:
        lab = memory.network_of(asyncio.get_running_loop())  # a lab in one process: its token
        token = lab.token if lab is not None else client_token((host, port))
    async with asyncio.timeout(timeout):
        peer = await connect(host, port)
        try:
            peer.send({**sent, "token": token} if token else sent)
            answer = await peer.read()
        finally:
            peer.close()
    if answer is None:
        raise ConnectionError(f"{host}:{port} closed without answering")
    if answer.get("refused"):
        raise PeerError(f"{host}:{port} {answer.get('error')}")
    return answer
