"""The exhaustive search over the real interlocking core: clean within a tight bound on the
shipped line, and able to fail -- a check switched off in the core, or a route's data made
wrong, is reached, named by station and route, by the shortest input sequence, which replays."""

from __future__ import annotations

import pytest

from ktcs_bench.errors import UsageError
from ktcs_bench.ixl import Interlocking
from ktcs_bench.station.model import Line
from ktcs_bench.verify.explore import Bound, explore_station, replay
from ktcs_bench.verify.report import run_verify
from tests.verify.seeds import reference, with_route


def test_a_station_is_clean_within_a_tight_bound() -> None:
    r = explore_station(reference(), 18, Bound(requests=1, trains=1))
    assert r.violations == []
    assert r.complete and r.states > 50 and r.transitions > r.states
    assert r.depth_reached >= 5  # a train ran through a route: set, points, signal, sections


def test_bound_text_parses_and_bad_text_is_a_usage_error() -> None:
    [b] = Bound.parse_all("requests=2,trains=1")
    assert (b.requests, b.trains, b.faults) == (2, 1, 0)
    assert len(Bound.parse_all("requests=1;faults=1")) == 2
    assert len(Bound.parse_all("")) >= 4
    for bad in ("requests", "nope=1", "requests=x", "requests=-1"):
        with pytest.raises(UsageError):
            Bound.parse_all(bad)


def _violation(line: Line, station: int, bound: Bound) -> tuple[list[str], list[tuple[str, ...]]]:
    r = explore_station(line, station, bound)
    assert r.violations, "the seeded defect was not found"
    v = r.violations[0]
    # the shortest sequence, fed again to a fresh core, reaches the same violation
    assert replay(line, station, bound, v.steps) == v.what
    return v.what, v.steps


def test_the_direction_check_switched_off_is_found(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Interlocking, "direction_check_disabled_for_tests", True)
    what, steps = _violation(reference(), 20, Bound(requests=1, env=2))
    # station 20 does not hold 1820's permission at start (its default direction is up)
    assert steps == [("route", "2192")]
    assert "signal 21" in what[0] and "route 2192" in what[0] and "1820" in what[0]


def test_the_occupancy_check_switched_off_is_found(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Interlocking, "occupancy_check_disabled_for_tests", True)
    what, steps = _violation(reference(), 18, Bound(requests=1, faults=1))
    # a route set, its points thrown, then one of its track circuits fails occupied: its
    # signal must go to stop at once
    assert steps[0][0] == "route" and steps[-1][0] == "tc_failed"
    assert f"{steps[-1][1]} occupied (route {steps[0][1]})" in what[0]


def test_a_track_circuit_dropped_from_a_route_is_found_by_the_core_search() -> None:
    # the route's data without TC2053B: the core lets 0111's signal clear over it occupied; the
    # search checks the path's track circuits as the geometry gives them
    line = with_route(reference(), 20, "0111", track_circuits=("TC2053A", "TC2055"),
                      release_sections=(("TC2053A",), ("TC2055",)))  # fmt: skip
    what, steps = _violation(line, 20, Bound(requests=1, faults=1))
    assert ("tc_failed", "TC2053B") in steps and ("route", "0111") in steps
    assert "TC2053B occupied (route 0111)" in what[0]


def test_verify_reports_data_defects_and_core_violations_naming_the_route(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    line = with_route(reference(), 20, "0111", overlap_points=())
    monkeypatch.setattr(Interlocking, "direction_check_disabled_for_tests", True)
    result = run_verify(line, bound_text="requests=1,env=1", stations=[20])
    assert any(f["route"] == "0111" and f["element"] == "34" for f in result["findings"])
    assert result["violations"] and "route 2192" in result["violations"][0]["what"][0]
    assert result["violations"][0]["steps"] == [["route", "2192"]]
    assert set(result) == {"states", "transitions", "bound", "seconds", "stations", "findings",
                           "violations"}  # fmt: skip
    assert result["stations"]["20"]["states"] >= 1


def test_searches_in_worker_processes_give_what_one_process_gives() -> None:
    alone = run_verify(reference(), bound_text="requests=1;trains=1", stations=[18, 22])
    side_by_side = run_verify(
        reference(), bound_text="requests=1;trains=1", stations=[18, 22], jobs=2
    )
    for key in ("states", "transitions", "findings", "violations"):
        assert alone[key] == side_by_side[key], key
    assert [s["states"] for s in alone["stations"].values()] == [
        s["states"] for s in side_by_side["stations"].values()
    ]
