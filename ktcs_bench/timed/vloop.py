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
web console, control ports) work beside the lab: `lab up --in-process --speed X`. When the
machine cannot keep up -- a timer is due more than `BEHIND` seconds of the lab's clock ago when
the loop comes to it -- it says so once, to whoever `watch_behind`s (the lab warns: every link
timing out after that is the clock's doing, not the devices').

Neither loop has wall-clock timers for the lab; `call_every_wall` runs housekeeping that must not
change the run (flushing files, a progress line, seeing a signal) between two steps of the loop,
about every so many seconds of wall time.

    loop = VirtualTimeLoop()
    loop.run_until_complete(main())         # or asyncio.Runner(loop_factory=VirtualTimeLoop)

This module imports asyncio only: no socket is opened by the virtual loop other than asyncio's own
self-pipe, which it never waits on.
"""

from __future__ import annotations

import asyncio
import contextvars
import heapq
import selectors
import time
from asyncio import base_events, events, format_helpers
from collections.abc import Callable
from typing import Any

from ktcs_bench.errors import KtcsError

MAX_SPEED = 50.0
"""The fastest scaled clock a whole lab in one process is started on (`lab up --in-process`).
Measured on a 2-core machine others shared: the reference lab with its trains takes a whole core
at 70x to 110x real time (7% of one at 5x, 18% at 20x; `lab simulate` runs it at about 230x by
CPU time); at 100x its links went down within 20 s and stayed down, at 50x they stayed up but for
a few resyncs while the machine was busiest."""

BEHIND = 1.0
"""Seconds of the lab's clock a timer may be overdue before a scaled loop calls itself behind:
a Type I link gives up on a frame's ACK after about that long (four ACK timeouts)."""


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
        loop._wall_chores()
        if timeout is None:
            raise _deadlock(loop)
        if timeout > 0:
            loop._advance(timeout)
        return []

    def close(self) -> None:
        self._keys.clear()

    def get_map(self) -> Any:
        return self._keys


def _deadlock(loop: VirtualTimeLoop) -> VirtualDeadlock:
    return VirtualDeadlock(
        f"nothing is ready and nothing is scheduled at virtual time {loop.time():.6f} s: "
        "every task waits for something that cannot come"
    )


def _report(handle: Any, exc: BaseException) -> None:
    """What `Handle._run` does with an exception its callback raised."""
    cb = format_helpers._format_callback_source(handle._callback, handle._args)
    context = {"message": f"Exception in callback {cb}", "exception": exc, "handle": handle}
    if handle._source_traceback:
        context["source_traceback"] = handle._source_traceback
    handle._loop.call_exception_handler(context)


def _fd(fileobj: Any) -> int:
    return fileobj if isinstance(fileobj, int) else int(fileobj.fileno())


class _WallChores:
    """`call_every_wall` for a loop (checked by its selector at every step)."""

    _chores: list[list[Any]]  # [period, next wall time, callback]

    def call_every_wall(self, period: float, callback: Callable[[], None]) -> None:
        """Call `callback()` between two steps of the loop about every `period` seconds of wall
        time (first after `period`), for as long as the loop runs. For what must not change the
        run: on the virtual clock a callback that schedules work on the loop makes the run depend
        on the machine's speed."""
        self._chores.append([period, time.monotonic() + period, callback])

    def _wall_chores(self) -> None:
        if not self._chores:
            return
        now = time.monotonic()
        for chore in self._chores:
            if now >= chore[1]:
                chore[1] = now + chore[0]
                chore[2]()


_MAX_SELECT: float = base_events.MAXIMUM_SELECT_TIMEOUT  # type: ignore[attr-defined]
_MIN_SCHEDULED: int = base_events._MIN_SCHEDULED_TIMER_HANDLES  # type: ignore[attr-defined]
_MIN_CANCELLED_FRACTION: float = base_events._MIN_CANCELLED_TIMER_HANDLES_FRACTION  # type: ignore[attr-defined]


class _When(float):
    """A timer's `when` on the virtual loop's heap, with its handle: compared as the float it
    is, in C, where asyncio's heap compares `TimerHandle`s by their `when` in Python. The
    comparisons give the same answers, so the heap orders timers exactly as asyncio's would
    (timers due at the same instant included); a lab's loop makes hundreds of thousands."""

    __slots__ = ("handle",)
    handle: Any  # the TimerHandle (its private fields are what asyncio's loop uses)


class _TimerHandle(events.TimerHandle):
    """asyncio's `TimerHandle`, made and cancelled without asking the loop whether it debugs
    (the loop makes these only when it does not): a lab's loop makes and cancels a handle for
    every step of every core's deadline, several for each frame on every link."""

    __slots__ = ()

    def __init__(
        self, when: float, callback: Callable[..., object], args: Any,
        loop: VirtualTimeLoop, context: Any,
    ) -> None:  # fmt: skip
        self._context = contextvars.copy_context() if context is None else context
        self._loop = loop
        self._callback = callback
        self._args = args
        self._cancelled = False
        self._repr = None
        self._source_traceback = None
        self._when = when
        self._scheduled = False

    def cancel(self) -> None:
        if not self._cancelled:
            if self._scheduled:  # what `BaseEventLoop._timer_handle_cancelled` counts
                self._loop._timer_cancelled_count += 1
            self._cancelled = True
            self._callback = None  # type: ignore[assignment]  # as asyncio does
            self._args = None  # type: ignore[assignment]


class VirtualTimeLoop(_WallChores, asyncio.SelectorEventLoop):
    """An asyncio loop on a virtual clock that starts at `start` and jumps from timer to timer.

    Its heap of timers holds `_When`s (`call_at`, `_run_once`: asyncio's own, step for step,
    on that heap)."""

    _scheduled: list[_When]
    _timer_cancelled_count: int
    _ready: Any
    _stopping: bool
    _clock_resolution: float
    _selector: selectors.BaseSelector

    def __init__(self, start: float = 0.0) -> None:
        self._virtual_now = start
        self._chores = []
        selector = _VirtualSelector()
        super().__init__(selector)
        selector.loop = self

    def time(self) -> float:
        return self._virtual_now

    def call_at(  # type: ignore[override]
        self, when: float, callback: Callable[..., object], *args: Any,
        context: Any = None,
    ) -> asyncio.TimerHandle:  # fmt: skip
        if when is None:
            raise TypeError("when cannot be None")
        if self._closed:  # type: ignore[attr-defined]  # `_check_closed`, inline
            raise RuntimeError("Event loop is closed")
        if self._debug:  # type: ignore[attr-defined]
            self._check_thread()  # type: ignore[attr-defined]
            self._check_callback(callback, "call_at")  # type: ignore[attr-defined]
            timer = events.TimerHandle(when, callback, args, self, context)
            if timer._source_traceback:  # type: ignore[attr-defined]
                del timer._source_traceback[-1]  # type: ignore[attr-defined]
        else:
            timer = _TimerHandle(when, callback, args, self, context)
        key = _When(when)
        key.handle = timer
        heapq.heappush(self._scheduled, key)
        timer._scheduled = True  # type: ignore[attr-defined]
        return timer

    def _run_once(self) -> None:
        """`BaseEventLoop._run_once` (Python 3.11) on the heap of `_When`s."""
        sched = self._scheduled
        count = len(sched)
        if count > _MIN_SCHEDULED and self._timer_cancelled_count / count > _MIN_CANCELLED_FRACTION:
            kept = []
            for key in sched:
                if key.handle._cancelled:
                    key.handle._scheduled = False
                else:
                    kept.append(key)
            heapq.heapify(kept)
            self._scheduled = sched = kept
            self._timer_cancelled_count = 0
        else:
            while sched and sched[0].handle._cancelled:
                self._timer_cancelled_count -= 1
                heapq.heappop(sched).handle._scheduled = False
        timeout: float | None = None
        if self._ready or self._stopping:
            timeout = 0
        elif sched:
            timeout = min(max(0, sched[0] - self._virtual_now), _MAX_SELECT)
        # `_VirtualSelector.select`, inline (it reports no I/O: nothing to process)
        if self._chores:
            self._wall_chores()
        if timeout is None:
            raise _deadlock(self)
        if timeout > 0:  # `_advance`, inline
            now = self._virtual_now
            target = now + timeout
            if sched and sched[0].handle._when <= target:
                target = sched[0].handle._when
            if target > now:
                self._virtual_now = target
        end_time = self._virtual_now + self._clock_resolution
        ready = self._ready
        while sched and sched[0] < end_time:
            due = heapq.heappop(sched).handle
            due._scheduled = False
            ready.append(due)
        handle: Any = None
        for _ in range(len(ready)):
            handle = ready.popleft()
            if handle._cancelled:
                continue
            if self._debug:  # type: ignore[attr-defined]
                try:
                    self._current_handle = handle
                    handle._run()
                finally:
                    self._current_handle = None
            else:  # `Handle._run`, inline: a lab's loop runs a handle for every piece of a frame
                try:
                    handle._context.run(handle._callback, *handle._args)
                except (SystemExit, KeyboardInterrupt):
                    raise
                except BaseException as exc:
                    _report(handle, exc)
        handle = None  # no cycle through the handle when a callback raised

    def _advance(self, timeout: float) -> None:
        """Move the clock to the earliest timer (asyncio asked to wait `timeout` for it): exactly
        to its `when`, so the timer is due on the next look, never a rounding short of it."""
        scheduled = self._scheduled
        target = self._virtual_now + timeout
        if scheduled and scheduled[0].handle.when() <= target:
            target = scheduled[0].handle.when()
        self._virtual_now = max(self._virtual_now, target)


class _ScaledSelector(selectors.DefaultSelector):
    speed = 1.0
    loop: ScaledTimeLoop | None = None

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if self.loop is not None:
            self.loop._wall_chores()
            self.loop._check_behind()
        return super().select(None if timeout is None else timeout / self.speed)


class ScaledTimeLoop(_WallChores, asyncio.SelectorEventLoop):
    """An asyncio loop whose clock runs `speed` times the wall clock, from `start`; real I/O."""

    def __init__(self, speed: float = 1.0, start: float = 0.0) -> None:
        selector = _ScaledSelector()
        super().__init__(selector)
        if not speed > 0:
            self.close()
            raise ValueError(f"speed must be > 0, not {speed}")
        selector.speed = speed
        selector.loop = self
        self.speed = speed
        self._origin = time.monotonic()
        self._start = start
        self._chores = []
        self.behind = 0.0  # the most a timer due since `watch_behind` has been late
        self._on_behind: Callable[[float], None] | None = None
        self._watched_from: float | None = None

    def time(self) -> float:
        return self._start + (time.monotonic() - self._origin) * self.speed

    def watch_behind(self, on_behind: Callable[[float], None]) -> None:
        """From now on, call `on_behind(late)` once, the first time the loop comes to a timer
        more than `BEHIND` seconds of its clock after it was due (`late`: by how much). Timers
        due before now do not count: a lab's start is one long step, not a clock running away."""
        self._on_behind = on_behind
        self._watched_from = self.time()
        self.behind = 0.0

    def _check_behind(self) -> None:
        """How late the earliest timer is (asyncio has dropped cancelled ones from the head)."""
        scheduled: list[asyncio.TimerHandle] = self._scheduled  # type: ignore[attr-defined]
        if self._watched_from is None or not scheduled:
            return
        due = scheduled[0].when()
        late = self.time() - due
        if due < self._watched_from or late <= self.behind:
            return
        self.behind = late
        if late > BEHIND and self._on_behind is not None:
            on_behind, self._on_behind = self._on_behind, None  # once
            on_behind(late)
