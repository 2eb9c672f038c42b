"""The pty adapter: a tap between two pty pairs, for a Type I link.

Device a opens `paths[a]`, device b opens `paths[b]`; the tap reads both masters and writes what
the core delivers to the other one. A pty nobody reads keeps at most PTY_PENDING_MAX bytes queued
(the oldest are dropped and counted). `cut` loses the bytes (the core's fault injectors do it).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from dataclasses import dataclass, field
from typing import Any

from ktcs_bench.errors import PeerError
from ktcs_bench.tap.runner import Tap

PTY_PENDING_MAX = 1 << 20  # bytes queued for a pty nobody reads before the oldest are dropped


@dataclass
class _Pty:
    master: int
    slave: int
    path: str
    pending: bytearray = field(default_factory=bytearray)
    writing: bool = False
    dropped: int = 0


class PtyTap(Tap):
    """A tap between two ptys: device a opens `paths[a]`, device b opens `paths[b]`.

    with PtyTap(names=("ixl", "atc")) as tap:
        ixl = serial.Serial(tap.paths["ixl"]); atc = serial.Serial(tap.paths["atc"])
    """

    kind = "pty"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._ptys: dict[str, _Pty] = {}
        # open the ptys now, so `paths` is known before start()
        try:
            for end in self.names:
                master, slave = os.openpty()
                tty.setraw(slave)
                os.set_blocking(master, False)
                self._ptys[end] = _Pty(master, slave, os.ttyname(slave))
        except OSError as exc:
            self._close_fds()
            raise PeerError(f"cannot create a pty: {exc}") from None

    @property
    def paths(self) -> dict[str, str]:
        return {end: p.path for end, p in self._ptys.items()}

    def _ends_info(self) -> dict[str, Any]:
        return {"paths": self.paths}

    def _other(self, end: str) -> str:
        return self.names[1] if end == self.names[0] else self.names[0]

    async def _open_ends(self) -> None:
        loop = asyncio.get_running_loop()
        for end, p in self._ptys.items():
            loop.add_reader(p.master, self._readable, end)

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
