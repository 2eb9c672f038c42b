"""One timer shape for every sans-I/O core, and the two drivers that honour it.

A core with time-driven behaviour (the Type I link, the Type II sessions, the interlocking, the
trackside, the train's ATP cycle, a fault injector, a tap's recorder, a virtual wire) is `Timed`:

* `next_deadline() -> float | None` -- the earliest `now` at which `handle_timer` has something to
  do; None while only an input can give it work. Any call may move it: a driver re-reads it after
  every call it makes, timer or input.
* `handle_timer(now) -> output` -- does everything due by `now`. Called early it does nothing that
  was not due (so a driver whose clock fires a hair early, or that calls every core of an
  instant, is never wrong); `now` never goes back.

Outputs are collected one way: every call of a core -- `handle_timer` and each input (`receive`,
`control`, `receive_data`, ...) -- returns that core's output object (`IxlOutput`, `FieldOutput`,
`CycleOutputs`, a list of link events, the bytes a wire delivers), so one sink per core takes
what it produced, whichever call produced it. Two things are collected otherwise: a link's bytes
for its wire, which its driver takes with `data_to_send` after every call (as h11 and aioquic
do), and a fault injector's bytes -- its `feed` only queues, what it lets through comes out of
`handle_timer(now)`, called after each `feed`.

Exactly one driver per clock:

* `ktcs_bench.timed.aio.LoopTimer` -- the wall clock (an asyncio loop's). One timer handle at the
  core's deadline; whoever feeds the core input calls `poke()` and the handle moves. Every emulator
  device, link runner, Type II pump, tap and the console's demo stations run on it.
* `ktcs_bench.timed.virtual.VirtualClock` -- a virtual clock holding any number of cores, jumping
  from the earliest deadline to the next. The virtual wire (`transport.virtual`), the scenario
  runner and the bench-less station rig (`ixl.rig`) run on it.

This module and `virtual` are pure (no I/O, no clock): a core may import them. `aio` is the
asyncio adapter: only the adapters above the cores import it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

Out = TypeVar("Out")
Out_co = TypeVar("Out_co", covariant=True)


class Timed(Protocol[Out_co]):
    """A sans-I/O core with deadlines (see the module docstring for the contract)."""

    def next_deadline(self) -> float | None: ...

    def handle_timer(self, now: float) -> Out_co: ...


Sink = Callable[[float, Out], None]
"""Where a driver hands a core's output: `sink(now, output)`."""

__all__ = ["Out", "Sink", "Timed"]
