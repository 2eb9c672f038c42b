"""asyncio event loops on a virtual clock: the whole lab in one process (SPEC §11).

`VirtualTimeLoop` is an asyncio event loop whose `time()` is virtual: when no callback is ready it
does not wait but jumps straight to the earliest scheduled timer. Everything that takes its time
from the loop -- `LoopTimer`, `asyncio.sleep`, `asyncio.timeout`, the devices' `now()` -- runs on
that clock unchanged, as fast as the machine allows, and the run is deterministic: the same
callbacks in the same order for the same inputs (no real I/O can wake it; threads must not feed it).
With nothing ready and nothing scheduled nothing can ever happen again: `select` raises
`VirtualDeadlock` instead of hanging.

`ScaledTimeLoop` is the same loop on a scaled wall clock: `time()` = `speed` × the wall time since
it was made, and the selector really waits (the timeout divided by `speed`), so real sockets (the
web console, control ports) work beside the lab: `lab up --in-process --speed X`.

    loop = VirtualTimeLoop()
    loop.run_until_complete(main())         # or asyncio.Runner(loop_factory=VirtualTimeLoop)

This module imports asyncio only: no socket is opened by the virtual loop other than asyncio's own
self-pipe, which it never waits on.
"""

from __future__ import annotations

import asyncio
import selectors
import time
from typing import Any

from ktcs_bench.errors import KtcsError


class VirtualDeadlock(KtcsError):
    """The virtual loop has nothing ready and nothing scheduled: it would wait forever."""


class _VirtualSelector(selectors.BaseSelector):
    """A selector that never blocks: asked to wait `timeout`, it moves the loop's clock to the
    earliest timer instead (and reports no I/O)."""

    def __init__(self) -> None:
        self._keys: dict[Any, selectors.SelectorKey] = {}
        self.loop: VirtualTimeLoop | None = None

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        key = selectors.SelectorKey(fileobj, _fd(fileobj), events, data)
        self._keys[fileobj] = key
        return key

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._keys.pop(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        self.unregister(fileobj)
        return self.register(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        loop = self.loop
        assert loop is not None
        if timeout is None:
            raise VirtualDeadlock(
                f"nothing is ready and nothing is scheduled at virtual time {loop.time():.6f} s: "
                "every task waits for something that cannot come"
            )
        if timeout > 0:
            loop._advance(timeout)
        return []

    def close(self) -> None:
        self._keys.clear()

    def get_map(self) -> Any:
        return self._keys


def _fd(fileobj: Any) -> int:
    return fileobj if isinstance(fileobj, int) else int(fileobj.fileno())


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio loop on a virtual clock that starts at `start` and jumps from timer to timer."""

    def __init__(self, start: float = 0.0) -> None:
        self._virtual_now = start
        selector = _VirtualSelector()
        super().__init__(selector)
        selector.loop = self

    def time(self) -> float:
        return self._virtual_now

    def _advance(self, timeout: float) -> None:
        """Move the clock to the earliest timer (asyncio asked to wait `timeout` for it): exactly
        to its `when`, so the timer is due on the next look, never a rounding short of it."""
        scheduled: list[asyncio.TimerHandle] = self._scheduled  # type: ignore[attr-defined]
        target = self._virtual_now + timeout
        if scheduled and scheduled[0].when() <= target:
            target = scheduled[0].when()
        self._virtual_now = max(self._virtual_now, target)


class _ScaledSelector(selectors.DefaultSelector):
    speed = 1.0

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        return super().select(None if timeout is None else timeout / self.speed)


class ScaledTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio loop whose clock runs `speed` times the wall clock, from `start`; real I/O."""

    def __init__(self, speed: float = 1.0, start: float = 0.0) -> None:
        selector = _ScaledSelector()
        super().__init__(selector)
        if not speed > 0:
            self.close()
            raise ValueError(f"speed must be > 0, not {speed}")
        selector.speed = speed
        self.speed = speed
        self._origin = time.monotonic()
        self._start = start

    def time(self) -> float:
        return self._start + (time.monotonic() - self._origin) * self.speed
