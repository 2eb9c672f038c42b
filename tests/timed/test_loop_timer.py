"""The wall-clock driver: one timer handle at a core's deadline, moved by input, never polling."""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any, TypeVar

from ktcs_bench.timed.aio import LoopTimer


class Alarm:
    """A core whose deadlines are set by hand; every call is logged with its `now`."""

    def __init__(self, *times: float) -> None:
        self.times = sorted(times)
        self.calls: list[float] = []

    def next_deadline(self) -> float | None:
        return self.times[0] if self.times else None

    def handle_timer(self, now: float) -> list[float]:
        self.calls.append(now)
        fired = [t for t in self.times if t <= now]
        self.times = [t for t in self.times if t > now]
        return fired


T = TypeVar("T")


def run(coro: Coroutine[Any, Any, T]) -> T:
    return asyncio.run(asyncio.wait_for(coro, 10))


def test_it_calls_the_core_at_each_deadline_not_before_and_hands_the_output_on() -> None:
    async def main() -> tuple[list[float], list[tuple[float, list[float]]]]:
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        deadlines = [t0 + 0.05, t0 + 0.10]
        core = Alarm(*deadlines)
        done = asyncio.Event()
        out: list[tuple[float, list[float]]] = []

        def sink(now: float, fired: list[float]) -> None:
            out.append((now, fired))
            if not core.times:
                done.set()

        LoopTimer(core, sink).poke()
        await done.wait()
        return deadlines, out

    deadlines, out = run(main())
    assert [fired for _, fired in out if fired] == [[deadlines[0]], [deadlines[1]]]
    assert all(now >= fired[0] for now, fired in out if fired)  # never early


def test_input_moves_the_handle_to_the_new_earliest_deadline() -> None:
    async def main() -> tuple[float, float]:
        loop = asyncio.get_running_loop()
        far = loop.time() + 60.0
        core = Alarm(far)
        fired = asyncio.Event()
        timer = LoopTimer(core, lambda now, out: fired.set())
        timer.poke()
        core.times.insert(0, loop.time() + 0.05)  # an input brought an earlier deadline
        timer.poke()
        await fired.wait()
        return loop.time(), far

    woke, far = run(main())
    assert woke < far - 50.0  # woken by the new deadline, not the old one


def test_a_core_without_a_deadline_is_never_called() -> None:
    async def main() -> Alarm:
        loop = asyncio.get_running_loop()
        idle = Alarm(loop.time() + 0.02)
        LoopTimer(idle, lambda now, out: None).poke()
        later = Alarm(loop.time() + 0.3)  # the signal that time has passed well beyond
        passed = asyncio.Event()
        LoopTimer(later, lambda now, out: passed.set()).poke()
        await passed.wait()
        return idle

    idle = run(main())
    assert len(idle.calls) == 1  # its one deadline; then no deadline, no call: no polling


def test_a_cancelled_timer_no_longer_calls_its_core() -> None:
    async def main() -> Alarm:
        loop = asyncio.get_running_loop()
        core = Alarm(loop.time() + 0.02)
        timer = LoopTimer(core, lambda now, out: None)
        timer.poke()
        timer.cancel()
        timer.poke()  # after cancel: ignored
        later = Alarm(loop.time() + 0.2)
        passed = asyncio.Event()
        LoopTimer(later, lambda now, out: passed.set()).poke()
        await passed.wait()
        return core

    assert run(main()).calls == []


def test_origin_gives_the_core_its_own_time_scale() -> None:
    async def main() -> tuple[list[float], float]:
        loop = asyncio.get_running_loop()
        origin = loop.time()
        core = Alarm(0.05)  # 50 ms after the origin, on the core's scale
        fired = asyncio.Event()
        timer = LoopTimer(core, lambda now, out: fired.set(), origin=origin)
        timer.poke()
        await fired.wait()
        return core.calls, loop.time() - origin

    calls, elapsed = run(main())
    assert len(calls) == 1 and 0.05 <= calls[0] <= elapsed
