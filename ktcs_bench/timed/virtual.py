"""The virtual-clock driver: any number of `Timed` cores on one clock that jumps from deadline to
deadline, deterministically. Nothing here sleeps or reads a clock.

    clock = VirtualClock()
    clock.add(ixl, lambda now, out: ...)        # a core and the sink of its timer outputs
    clock.add(wire, lambda now, data: link.receive_data(data, now))
    clock.run_until(60.0)                       # or run_for, step; stop=... ends early

An instant (one value of `now`) is run in passes: each pass calls `handle_timer` on every core
whose deadline has come, in the order the cores were added, and hands each output to its sink;
a sink may feed other cores (an input arriving now), so passes repeat until no core is due. Then
the clock jumps to the earliest deadline left. Input fed from outside (a test sending a message)
is simply fed to the core at `clock.now`; the clock asks every core its deadline afresh at each
jump, so nothing has to be told.

The cost of an instant is one `next_deadline()` per core and pass: a whole lab of cores, links
and wires (some tens) costs microseconds per instant, beside the cores' own work.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ktcs_bench.timed import Out, Sink, Timed

MAX_PASSES = 10_000
"""Passes in one instant before the clock calls it a bug (a deadline that never moves past now)."""


@dataclass(eq=False, slots=True)
class _Entry:
    core: Timed[Any]
    sink: Sink[Any] | None


class VirtualClock:
    """Cores on one virtual clock; `now` is its time (seconds, from `start`)."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start
        self._entries: list[_Entry] = []

    def add(self, core: Timed[Out], sink: Sink[Out] | None = None) -> None:
        """Drive `core`; its timer outputs go to `sink(now, output)` (dropped without one)."""
        self._entries.append(_Entry(core, sink))

    def remove(self, core: Timed[Any]) -> None:
        self._entries = [e for e in self._entries if e.core is not core]

    @property
    def cores(self) -> list[Timed[Any]]:
        return [e.core for e in self._entries]

    def next_time(self) -> float | None:
        """The earliest deadline of any core (None: nothing will happen without input)."""
        best: float | None = None
        for e in self._entries:
            d = e.core.next_deadline()
            if d is not None and (best is None or d < best):
                best = d
        return best

    def step(self) -> bool:
        """Jump to the next deadline and run that instant; False when no core has one."""
        entries, deadlines, t = self._scan()
        if t is None:
            return False
        if t > self.now:
            self.now = t
        self._call(self._due(entries, deadlines), self.now)
        self.run_due()
        return True

    def run_due(self) -> None:
        """Run every core due at `now`, pass after pass, until none is."""
        for _ in range(MAX_PASSES):
            entries, deadlines, t = self._scan()
            if t is None or t > self.now:
                return
            self._call(self._due(entries, deadlines), self.now)
        raise RuntimeError(f"a core's deadline does not move past {self.now}")

    def run_until(self, t: float, stop: Callable[[], bool] | None = None) -> None:
        """Run every instant up to and including `t` (or until `stop()` holds after one); the
        clock then reads `t` (or the instant it stopped at)."""
        ran = False
        passes = 0  # at this instant
        while True:
            # one look at the deadlines both ends an instant and finds the next one
            entries, deadlines, nxt = self._scan()
            if nxt is None or nxt > self.now:  # nothing more is due now: the instant is over
                if ran and stop is not None and stop():
                    return
                if nxt is None or nxt > t:
                    self.now = max(self.now, t)
                    return
                self.now = nxt
                passes = 0
            passes += 1
            if passes > MAX_PASSES:
                raise RuntimeError(f"a core's deadline does not move past {self.now}")
            self._call(self._due(entries, deadlines), self.now)
            ran = True

    def run_for(self, dt: float, stop: Callable[[], bool] | None = None) -> None:
        self.run_until(self.now + dt, stop)

    def _scan(self) -> tuple[list[_Entry], list[float | None], float | None]:
        """Every core's deadline, and the earliest."""
        entries = self._entries
        deadlines = [e.core.next_deadline() for e in entries]
        return entries, deadlines, min((d for d in deadlines if d is not None), default=None)

    def _due(self, entries: list[_Entry], deadlines: list[float | None]) -> list[_Entry]:
        now = self.now
        return [e for e, d in zip(entries, deadlines, strict=True) if d is not None and d <= now]

    @staticmethod
    def _call(due: list[_Entry], now: float) -> None:
        for e in due:
            out = e.core.handle_timer(now)
            if e.sink is not None:
                e.sink(now, out)
