"""Helpers for the socket tests: run a coroutine with a hard limit, and a frame-aware TCP proxy
that sits between an IXL and the CTC on 127.0.0.1 and can drop, damage, freeze or cut traffic."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Coroutine
from typing import Any

from ktcs_bench.codec import Frame, StreamDecoder, get_profile

PROFILE = get_profile("ktcs-type2")
LIMIT = 30.0


def run(coro: Coroutine[Any, Any, None]) -> None:
    async def main() -> None:
        await asyncio.wait_for(coro, LIMIT)

    asyncio.run(main())


async def poll_until(predicate: Callable[[], bool], timeout: float = 10.0) -> None:
    """Wait until `predicate()` holds, for what no client or server event announces (what the
    proxy saw, the time on the loop)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate():
        if loop.time() > deadline:
            raise TimeoutError("condition not reached")
        await asyncio.sleep(0.005)


CUT = object()  # returned by a hook: forward half of this frame, then cut the connection

Hook = Callable[[Frame], "bytes | None | object"]


class Proxy:
    """Listens on 127.0.0.1:0 and forwards to 127.0.0.1:`target`.

    `up` (IXL -> CTC) and `down` (CTC -> IXL) hooks see each frame and return the bytes to forward
    (the frame's raw bytes to pass it, altered bytes to damage it, None to drop it, CUT to cut).
    `frozen` stops all forwarding without closing anything (a silent link).
    """

    def __init__(self, target: int) -> None:
        self.target = target
        self.up: Hook | None = None
        self.down: Hook | None = None
        self.frozen = False
        self.seen_up: list[Frame] = []
        self.seen_down: list[Frame] = []
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._writers: list[asyncio.StreamWriter] = []

    async def start(self) -> int:
        self._server = await asyncio.start_server(self._handle, "127.0.0.1", 0)
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        assert self._server is not None
        self._server.close()
        for w in self._writers:
            w.transport.abort()
        for t in list(self._tasks):
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self._server.wait_closed()

    def cut_all(self) -> None:
        for w in self._writers:
            w.transport.abort()

    async def _handle(self, cr: asyncio.StreamReader, cw: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        try:
            sr, sw = await asyncio.open_connection("127.0.0.1", self.target)
            self._writers += [cw, sw]
            pair = (cw, sw)
            await asyncio.gather(
                self._pump(cr, sw, pair, "up"), self._pump(sr, cw, pair, "down"),
                return_exceptions=True,
            )  # fmt: skip
        finally:
            for w in (cw,) + ((sw,) if "sw" in locals() else ()):
                w.transport.abort()
            self._tasks.discard(task)

    async def _pump(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        pair: tuple[asyncio.StreamWriter, asyncio.StreamWriter],
        way: str,
    ) -> None:
        dec = StreamDecoder(PROFILE)
        seen = self.seen_up if way == "up" else self.seen_down
        try:
            while data := await reader.read(65536):
                if self.frozen:
                    continue
                out = bytearray()
                for rec in dec.feed(data):
                    if not isinstance(rec, Frame):
                        out += rec.raw
                        continue
                    seen.append(rec)
                    hook = self.up if way == "up" else self.down
                    result = rec.raw if hook is None else hook(rec)
                    if result is CUT:
                        writer.write(bytes(out) + rec.raw[: len(rec.raw) // 2])
                        await asyncio.sleep(0.01)
                        for w in pair:
                            w.transport.abort()
                        return
                    if isinstance(result, bytes):
                        out += result
                if out:
                    writer.write(bytes(out))
        except (ConnectionError, OSError):
            pass
        finally:
            with contextlib.suppress(Exception):
                writer.transport.abort()


def damage(raw: bytes) -> bytes:
    """Flip the CRC's last byte."""
    return raw[:-1] + bytes([raw[-1] ^ 0xFF])
