"""The virtual-clock driver: cores on one clock, jumping from deadline to deadline."""

from __future__ import annotations

from ktcs_bench.timed.virtual import VirtualClock
from ktcs_bench.transport.virtual import VirtualBench
from ktcs_bench.type1 import Type1Link
from tests.type1.helpers import CONFIG, PROFILE, provider


class Alarm:
    """A core with a list of deadlines; every call is logged as (now, name)."""

    def __init__(self, name: str, times: list[float], log: list[tuple[float, str]]) -> None:
        self.name, self.times, self.log = name, sorted(times), log

    def next_deadline(self) -> float | None:
        return self.times[0] if self.times else None

    def handle_timer(self, now: float) -> list[float]:
        self.log.append((now, self.name))
        fired = [t for t in self.times if t <= now]
        self.times = [t for t in self.times if t > now]
        return fired


def test_it_jumps_from_deadline_to_deadline_calling_only_the_cores_due() -> None:
    log: list[tuple[float, str]] = []
    clock = VirtualClock()
    clock.add(Alarm("a", [1.0, 3.0], log))
    clock.add(Alarm("b", [2.0, 3.0], log))
    clock.run_until(2.5)
    assert log == [(1.0, "a"), (2.0, "b")] and clock.now == 2.5
    clock.run_until(10.0)
    assert log[2:] == [(3.0, "a"), (3.0, "b")] and clock.now == 10.0
    assert not clock.step()  # nothing left: no instant to run


def test_cores_due_together_run_in_the_order_they_were_added_and_sinks_get_the_output() -> None:
    log: list[tuple[float, str]] = []
    got: list[tuple[float, list[float]]] = []
    clock = VirtualClock()
    clock.add(Alarm("second-made", [1.0], log), lambda now, out: got.append((now, out)))
    clock.add(Alarm("first-made", [1.0], log))
    assert clock.step()
    assert log == [(1.0, "second-made"), (1.0, "first-made")]
    assert got == [(1.0, [1.0])]


def test_an_input_a_sink_feeds_is_handled_in_the_same_instant() -> None:
    log: list[tuple[float, str]] = []
    late = Alarm("late", [], log)
    clock = VirtualClock()
    clock.add(late)
    clock.add(Alarm("early", [1.0], log), lambda now, out: late.times.append(now))
    clock.add(Alarm("after", [2.0], log))
    clock.step()
    assert log == [(1.0, "early"), (1.0, "late")]  # a second pass at 1.0, before 2.0
    assert clock.now == 1.0


def test_run_until_stops_after_the_instant_where_stop_holds() -> None:
    log: list[tuple[float, str]] = []
    clock = VirtualClock()
    clock.add(Alarm("a", [1.0, 2.0, 3.0], log))
    clock.run_until(10.0, stop=lambda: len(log) == 2)
    assert log == [(1.0, "a"), (2.0, "a")] and clock.now == 2.0


def pair(name: str, clock: VirtualClock | None = None) -> tuple[Type1Link, VirtualBench]:
    a = Type1Link(PROFILE, CONFIG, f"{name}-a", state_provider=provider({1: 1, 2: 0}))
    b = Type1Link(PROFILE, CONFIG, f"{name}-b", state_provider=provider({1: 0}))
    return a, VirtualBench(a, b, clock=clock)


def test_one_clock_holds_many_links_and_each_runs_as_it_would_alone() -> None:
    clock = VirtualClock()
    shared = [pair(f"p{k}", clock) for k in range(3)]
    for k, (a, bench) in enumerate(shared):
        bench.send(a, a.message("CHANGE", items=[[2, k]]))
    clock.run_until(2.0)
    for k, (_, bench) in enumerate(shared):
        a, alone = pair(f"p{k}")
        alone.send(a, a.message("CHANGE", items=[[2, k]]))
        alone.run_until(2.0)
        assert bench.events == alone.events and bench.events
        assert bench.ab.arrived == alone.ab.arrived and bench.ba.arrived == alone.ba.arrived
    assert len(clock.cores) == 12  # three pairs: two links and two wires each
