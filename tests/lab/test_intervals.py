"""Invariants 5 and 6 (lab.intervals) and a train off the blades (invariant 3), fed snapshots
straight in through the `SafetyChecker` the search and `lab simulate` use."""

from __future__ import annotations

from collections.abc import Mapping

from ktcs_bench.lab.invariants import (
    LabSnapshot,
    MachineState,
    SafetyChecker,
    StationState,
    TrainState,
    Violation,
)
from ktcs_bench.lab.safety import LASTING
from ktcs_bench.station import load_line

LINE = load_line()


def station(number: int, routes: Mapping[str, str] = {}, machines: Mapping[str, MachineState] | None = None) -> StationState:  # fmt: skip
    names = {r.name: "idle" for r in LINE.station(number).routes}
    return StationState(number, routes={**names, **routes}, held={}, machines=machines)


def look(t: float, trains: Mapping[str, tuple[float, float, str]], *stations: StationState) -> LabSnapshot:  # fmt: skip
    return LabSnapshot(
        t,
        {n: TrainState(n, h, tl, tr) for n, (h, tl, tr) in trains.items()},
        frozenset(),
        {},
        {s.station: s for s in stations},
    )


def kinds(found: list[Violation]) -> set[str]:
    return {v.kind for v in found}


def test_departures_into_one_interval_from_both_ends_break_invariant_5() -> None:
    checker = SafetyChecker(LINE)
    one_end = checker.feed(look(0, {}, station(18, {"1191": "set"}), station(20)))
    assert "opposing_departures" not in kinds(one_end)
    both = checker.feed(look(1, {}, station(18, {"1191": "set"}), station(20, {"2192": "setting"})))
    [v] = [v for v in both if v.kind == "opposing_departures"]
    assert v.invariant == 5 and v.where == "1820", v
    assert "opposing_departures" in LASTING


def test_two_trains_in_one_interval_facing_each_other_break_invariant_6() -> None:
    checker = SafetyChecker(LINE)
    same_way = checker.feed(look(0, {"a": (3000, 2800, "1"), "b": (5000, 4800, "1")}))
    assert "opposing_trains" not in kinds(same_way)
    head_on = checker.feed(look(1, {"a": (3000, 2800, "1"), "b": (4800, 5000, "1")}))
    [v] = [v for v in head_on if v.kind == "opposing_trains"]
    assert v.invariant == 6 and v.where == "1820", v
    assert "opposing_trains" in LASTING


def test_a_train_entering_an_interval_against_a_locked_departure_breaks_invariant_6() -> None:
    checker = SafetyChecker(LINE)
    st18, st20 = station(18, {"1191": "set"}), station(20)
    checker.feed(look(0, {"up": (1150, 950, "1")}, st18, st20))
    ok = checker.feed(look(1, {"up": (1250, 1050, "1")}, st18, st20))  # with its own departure
    assert "entered_against_departure" not in kinds(ok)
    checker = SafetyChecker(LINE)
    st20 = station(20, {"2192": "set"})
    checker.feed(look(0, {"up": (1150, 950, "1")}, st18, st20))
    found = checker.feed(look(1, {"up": (1250, 1050, "1")}, st18, st20))
    [v] = [v for v in found if v.kind == "entered_against_departure"]
    assert v.invariant == 6 and "2192" in v.text, v


def test_a_train_through_a_facing_point_onto_the_leg_it_does_not_lie_for_breaks_invariant_3() -> (
    None
):
    """Station 18's point 31 (at 550 m, its toe met running up): lying normal (track 1), an up
    train whose head is on track 2 past it ran through it; on track 1 it did not."""
    checker = SafetyChecker(LINE)
    normal = {"31": MachineState("normal", "normal", False), "32": MachineState("normal", "normal", False)}  # fmt: skip
    fine = checker.feed(look(0, {"t": (700, 500, "1")}, station(18, machines=normal)))
    assert "through_point_not_lying" not in kinds(fine)
    found = checker.feed(look(1, {"t": (700, 500, "2")}, station(18, machines=normal)))
    [v] = [v for v in found if v.kind == "through_point_not_lying"]
    assert v.invariant == 3 and v.where == "18/31", v
