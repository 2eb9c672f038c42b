"""The wall-clock driver: one `Timed` core on a running asyncio loop's clock.

    timer = LoopTimer(core, lambda now, out: apply(out))
    ...on input:  apply(core.receive(x, timer.now())); timer.poke()
    timer.fire()          # once, when the core should start counting (a link opening)
    timer.cancel()        # when the adapter stops

It keeps one `TimerHandle` at the core's `next_deadline()`: it sleeps until the earliest deadline
and wakes on input (the adapter's `poke()` moves the handle after every input). When the handle
fires it calls `handle_timer(now)`, hands the output to the sink, and re-arms. No polling: a core
without a deadline costs nothing.

`origin` puts a core on its own time scale: it sees `loop.time() - origin` (a train counts its
cycles from its start, a station rig from its virtual zero).
"""

from __future__ import annotations

import asyncio
from typing import Generic

from ktcs_bench.timed import Out, Sink, Timed


class LoopTimer(Generic[Out]):
    """Drive `core`'s deadlines on the running loop; its timer outputs go to `sink(now, out)`."""

    def __init__(self, core: Timed[Out], sink: Sink[Out], *, origin: float = 0.0) -> None:
        self.core = core
        self.sink = sink
        self.origin = origin
        self._handle: asyncio.TimerHandle | None = None
        self._at: float | None = None  # the core's deadline the handle is armed for
        self._stopped = False
        self._next_deadline = core.next_deadline  # asked after every input: bound once
        self._due = self._on_handle

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        return asyncio.get_running_loop()

    def now(self) -> float:
        """The core's `now`: the loop's clock less `origin`."""
        return asyncio.get_running_loop().time() - self.origin

    def poke(self) -> None:
        """The core was fed input (or may have a new deadline): move the handle to it."""
        if self._stopped:
            return
        deadline = self._next_deadline()
        handle = self._handle
        if handle is not None:
            if deadline == self._at:
                return
            handle.cancel()
        if deadline is None:
            self._handle = self._at = None
        else:
            self._handle = asyncio.get_running_loop().call_at(deadline + self.origin, self._due)
            self._at = deadline

    def fire(self, due: float | None = None) -> None:
        """Call the core's timer now, whatever its deadline (then re-arm). `due`: the deadline
        the handle was armed for -- the core's time has reached it, even where the loop's time
        less `origin` rounds a hair below it (so the core is never called with nothing due, again
        and again, at one instant of a virtual clock)."""
        if self._stopped:
            return
        now = self.now()
        if due is not None and now < due:
            now = due
        self.sink(now, self.core.handle_timer(now))
        self.poke()

    def cancel(self) -> None:
        """Stop driving the core (its adapter is closing); `poke` and `fire` do nothing after."""
        self._stopped = True
        self._disarm()

    def _disarm(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._handle = None
        self._at = None

    def _on_handle(self) -> None:
        """The handle is due: `fire(due)`, inline (every piece of every frame on a lab's virtual
        wires comes through here)."""
        due = self._at
        self._handle = None
        self._at = None
        if self._stopped:
            return
        now = asyncio.get_running_loop().time() - self.origin
        if due is not None and now < due:
            now = due
        self.sink(now, self.core.handle_timer(now))
        self.poke()
