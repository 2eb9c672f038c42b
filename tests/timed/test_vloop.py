"""The asyncio loops on a virtual and a scaled clock (issue 15 part 2)."""

from __future__ import annotations

import asyncio
import time

import pytest

from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.timed.vloop import ScaledTimeLoop, VirtualDeadlock, VirtualTimeLoop


def run(coro_fn, loop: asyncio.AbstractEventLoop | None = None):  # type: ignore[no-untyped-def]
    loop = loop or VirtualTimeLoop()
    try:
        return loop.run_until_complete(coro_fn())
    finally:
        loop.close()


def test_an_hour_of_sleeping_takes_no_wall_time_and_the_clock_reads_it() -> None:
    async def main() -> tuple[float, float]:
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        await asyncio.sleep(3600.0)
        return t0, loop.time()

    wall = time.monotonic()
    t0, t1 = run(main)
    assert t0 == 0.0 and t1 == 3600.0  # exactly: the clock jumps to the timer's own time
    assert time.monotonic() - wall < 60  # (would be an hour on a wall-clock loop)


def test_timers_run_in_time_order_and_the_same_order_every_run() -> None:
    def once() -> list[tuple[float, str]]:
        seen: list[tuple[float, str]] = []

        async def main() -> None:
            loop = asyncio.get_running_loop()
            for i, t in enumerate([5.0, 0.25, 5.0, 1.0, 0.25]):
                loop.call_at(t, lambda t=t, i=i: seen.append((loop.time(), f"{t}-{i}")))  # type: ignore[misc]
            await asyncio.sleep(10)

        run(main)
        return seen

    first = once()
    assert [t for t, _ in first] == [0.25, 0.25, 1.0, 5.0, 5.0]
    assert first == once()


def test_a_core_on_loop_timer_fires_at_its_deadlines() -> None:
    class Every:
        def __init__(self) -> None:
            self.at = 0.5

        def next_deadline(self) -> float:
            return self.at

        def handle_timer(self, now: float) -> float:
            if now >= self.at:
                self.at += 0.5
            return now

    fired: list[float] = []

    async def main() -> None:
        timer = LoopTimer(Every(), lambda now, out: fired.append(out))
        timer.poke()
        await asyncio.sleep(2.2)
        timer.cancel()

    run(main)
    assert fired == [0.5, 1.0, 1.5, 2.0]


def test_waiting_for_what_cannot_come_is_a_deadlock_not_a_hang() -> None:
    async def main() -> None:
        await asyncio.get_running_loop().create_future()

    with pytest.raises(VirtualDeadlock, match="nothing is scheduled"):
        run(main)


def test_the_scaled_loop_runs_its_clock_faster_than_the_wall() -> None:
    async def main() -> float:
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        await asyncio.sleep(20.0)
        return loop.time() - t0

    wall = time.monotonic()
    elapsed = run(main, ScaledTimeLoop(speed=200.0))
    assert elapsed >= 20.0
    assert time.monotonic() - wall < 10.0  # 20 s of a clock 200 times the wall's: 0.1 s


def test_a_speed_of_zero_is_refused() -> None:
    with pytest.raises(ValueError, match="speed"):
        ScaledTimeLoop(speed=0)


def test_a_core_with_an_origin_is_called_once_per_deadline_whatever_the_rounding() -> None:
    """The handle armed for deadline d fires at loop time d + origin; (d + origin) - origin can
    come out a hair below d in floating point (3.0000000000000004 + 0.1 - 0.1 == 3.0), and a core
    called then has nothing due, so the loop -- whose virtual clock does not move by itself -- would
    call it again and again at the same instant. The driver gives the core the deadline it fired
    for: one call per deadline."""

    class Cycle:
        def __init__(self) -> None:
            self.cycles, self.calls = 0, 0

        def next_deadline(self) -> float:
            return 0.1 + self.cycles * 0.1  # as a train's cycle: first + cycles x period

        def handle_timer(self, now: float) -> None:
            self.calls += 1
            if now >= self.next_deadline():
                self.cycles += 1
            elif self.calls > self.cycles + 10:  # spinning at one instant: end the run, fail
                asyncio.get_running_loop().stop()

    core = Cycle()

    async def main() -> None:
        timer = LoopTimer(core, lambda now, out: None, origin=0.1)
        timer.poke()
        await asyncio.sleep(10.05)
        timer.cancel()

    run(main)
    assert (
        core.cycles == 99
    )  # deadlines 0.1 .. 9.9 on the core's clock (origin 0.1: 10.0 on the loop's)
    assert core.calls == core.cycles, f"{core.calls - core.cycles} calls found nothing due"


def test_a_callback_that_raises_is_reported_as_asyncio_reports_it_and_the_loop_goes_on() -> None:
    """The virtual loop runs its handles itself (not through `Handle._run`): what a failing
    callback leaves is the same report to the exception handler as on asyncio's own loop."""

    def fail(what: str) -> None:
        raise RuntimeError(what)

    def reports(loop: asyncio.AbstractEventLoop) -> tuple[list[tuple[str, str]], list[str]]:
        seen: list[tuple[str, str]] = []
        after: list[str] = []
        loop.set_exception_handler(
            lambda loop, ctx: seen.append((ctx["message"], repr(ctx["exception"])))
        )

        async def main() -> None:
            loop = asyncio.get_running_loop()
            loop.call_later(0.01, fail, "late")
            loop.call_soon(fail, "soon")
            loop.call_later(0.02, after.append, "on")
            await asyncio.sleep(0.05)

        run(main, loop)
        return seen, after

    virtual, real = reports(VirtualTimeLoop()), reports(asyncio.new_event_loop())
    assert virtual == real  # the same messages and exceptions, in the same order
    assert [e for _, e in virtual[0]] == ["RuntimeError('soon')", "RuntimeError('late')"]
    assert all(m.startswith("Exception in callback ") and "fail(" in m for m, _ in virtual[0])
    assert virtual[1] == ["on"]  # the loop went on
