"""The virtual-wire adapter: a tap between the two ends of a Type I wire of the memory network,
for a lab run in one process (`transport.memory`).

Device a opens `virtual://LINK/a`, device b `virtual://LINK/b`; what a device's line delivers
(paced at the line rate by its transport, as a pty's writer paces it live) comes to the tap, and
what the core delivers goes to the other end at once -- the pty tap's place and behaviour, with no
file descriptor and no thread. Run it with `open_here()` on the lab's loop.
"""

from __future__ import annotations

import asyncio
from functools import partial
from typing import Any

from ktcs_bench.errors import UsageError
from ktcs_bench.tap.registry import TapEnds
from ktcs_bench.tap.runner import Tap
from ktcs_bench.transport.memory import VIRTUAL_SCHEME, SerialEnd, network_of


class WireTap(Tap):
    """A tap between `virtual://LINK/a` and `virtual://LINK/b` (LINK is the tap's `name`)."""

    kind = "wire"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if not self.name:
            raise UsageError("a wire tap needs the link's name")
        self._ends: dict[str, SerialEnd] = {}
        self._to: dict[str, SerialEnd] = {}  # by direction "a>b": the end it is delivered at

    @property
    def paths(self) -> dict[str, str]:
        """The endpoint each device opens."""
        return {end: f"{VIRTUAL_SCHEME}{self.name}/{end}" for end in self.names}

    def _ends_info(self) -> TapEnds:
        return {"paths": self.paths}

    async def _open_ends(self) -> None:
        net = network_of(asyncio.get_running_loop())
        if net is None:
            raise OSError("a wire tap runs on a loop with a memory network (a lab in one process)")
        a, b = self.names
        for end in (a, b):
            self._ends[end] = net.serial_end(f"{self.name}/{end}")
        for end, other in ((a, b), (b, a)):
            self._to[f"{other}>{end}"] = self._ends[end]  # what goes that way arrives here
        for end, other in ((a, b), (b, a)):
            self._ends[end].join = partial(self._line, f"{end}>{other}", self._ends[other])

    def _line(self, direction: str, to: SerialEnd, data: bytes, now: float) -> None:
        """What a device's line delivered (`_on_data`, on the tap's own clock), for the end `to`.
        On a clean link the bytes pass as `_apply` would pass them, without an output to build
        and read."""
        now = self.timer.now()
        records = self.core.passed(direction, data, now)
        if records is None:
            self._apply(self.core.receive(direction, data, now))
            return
        to.deliver(data)
        for r in records:
            for w in self._writers:
                w.write(r)
        if not self._closing:
            self.timer.poke()

    def _deliver(self, direction: str, data: bytes) -> None:
        end = self._to.get(direction)
        if end is not None:
            end.deliver(data)

    async def _close_ends(self) -> None:
        for end in self._ends.values():
            end.join = None
