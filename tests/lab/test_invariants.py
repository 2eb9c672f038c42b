"""The integrated system's invariants (`lab.invariants`) on hand-made snapshots of the reference
line: each check finds the breach it is for, and stays silent on the safe state next to it.

Station 20 on track 1, running up: signal 01 at 6000, TC2053A (point 31) 6000-6100, TC2053B
(point 33) 6100-6200, TC2055 6200-6800, exit signal 11 at 6800, overlap TC2057B (point 34)
6800-6900, then TC2057A (point 32) 6900-7000. The approach TC2047 is plain line, 5200-6000."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import pytest

from ktcs_bench.errors import ConfigError
from ktcs_bench.lab.invariants import (
    Geometry,
    LabSnapshot,
    MachineState,
    SafetyChecker,
    StationState,
    TrainState,
    Violation,
    danger_points,
    point_safety,
    train_separation,
    views_agree,
)
from ktcs_bench.lab.safety import Replay, load_replay
from ktcs_bench.station import load_line
from ktcs_bench.station_codes.stations import station_chart

LINE = load_line()
GEO = Geometry(LINE)
ROUTE_0111 = ["TC2053A", "TC2053B", "TC2055", "TC2057B", "31", "33", "34"]
AT_REST = {p.name: MachineState("normal", "normal", False) for p in LINE.station(20).points}


def station(
    routes: dict[str, str] | None = None,
    held: dict[str, list[str]] | None = None,
    machines: dict[str, MachineState] | None = None,
    **kw: object,
) -> StationState:
    names = [r.name for r in LINE.station(20).routes]
    status = dict.fromkeys(names, "idle") | (routes or {})
    return StationState(
        station=20,
        routes=status,
        held={r: frozenset(e) for r, e in (held or {}).items()},
        machines=AT_REST | (machines or {}),
        **kw,  # type: ignore[arg-type]
    )


def snap(t: float, trains: Mapping[str, tuple[float, float]], st20: StationState | None = None,
         occupied: frozenset[str] = frozenset()) -> LabSnapshot:  # fmt: skip
    return LabSnapshot(
        time=t,
        trains={n: TrainState(n, head, tail) for n, (head, tail) in trains.items()},
        occupied=occupied,
        tc_faults={},
        stations={20: st20 or station()},
    )


def kinds(found: list[Violation]) -> list[str]:
    return [v.kind for v in found]


# ------------------------------------------------------------------------------------------ 1


def test_two_trains_in_one_track_circuit_apart_from_each_other() -> None:
    found = train_separation(snap(0, {"A": (5450, 5350), "B": (5900, 5700)}), GEO)
    assert kinds(found) == ["shared_track_circuit"] and found[0].where == "TC2047"


def test_a_train_running_into_another() -> None:
    found = train_separation(snap(0, {"A": (5600, 5400), "B": (5700, 5500)}), GEO)
    assert "collision" in kinds(found)


def test_trains_in_successive_track_circuits_or_side_by_side_on_two_tracks_are_apart() -> None:
    assert train_separation(snap(0, {"A": (5150, 5000), "B": (5900, 5700)}), GEO) == []
    side_by_side = LabSnapshot(
        0.0,
        {"A": TrainState("A", 6500, 6300, "1"), "B": TrainState("B", 6500, 6300, "3")},
        frozenset(),
        {},
        {20: station()},
    )
    assert train_separation(side_by_side, GEO) == []


# ------------------------------------------------------------------------------------------ 2


def test_a_head_into_a_route_that_holds_the_track_is_safe() -> None:
    st = station({"0111": "set"}, {"0111": ROUTE_0111})
    before, after = snap(0, {"A": (5990, 5890)}, st), snap(1, {"A": (6010, 5910)}, st)
    assert danger_points(before, after, GEO) == []


def test_a_head_past_a_signal_with_no_route_or_a_route_still_being_set() -> None:
    for st in (station(), station({"0111": "setting"}, {"0111": ROUTE_0111})):
        before, after = snap(0, {"A": (5990, 5890)}, st), snap(1, {"A": (6010, 5910)}, st)
        found = danger_points(before, after, GEO)
        assert kinds(found) == ["danger_point"] and found[0].where == "TC2053A", found


def test_into_the_overlap_is_safe_beyond_its_end_is_a_danger_point() -> None:
    st = station({"0111": "entered"}, {"0111": ["TC2055", "TC2057B", "34"]})
    into = danger_points(snap(0, {"A": (6790, 6690)}, st), snap(1, {"A": (6810, 6710)}, st), GEO)
    assert into == []
    beyond = danger_points(snap(0, {"A": (6890, 6790)}, st), snap(1, {"A": (6910, 6810)}, st), GEO)
    assert kinds(beyond) == ["danger_point"] and beyond[0].where == "TC2057A"


def test_a_head_running_several_track_circuits_between_looks_is_judged_on_each() -> None:
    st = station({"0111": "set"}, {"0111": ["TC2053A", "TC2053B"]})  # TC2055 not held
    found = danger_points(snap(0, {"A": (5990, 5890)}, st), snap(1, {"A": (6250, 6150)}, st), GEO)
    assert [v.where for v in found] == ["TC2055"]


def test_the_plain_line_is_protected_by_the_block() -> None:
    before, after = snap(0, {"A": (5190, 5090)}), snap(1, {"A": (5210, 5110)})
    assert danger_points(before, after, GEO) == []


def test_a_head_reaching_the_rear_of_the_train_ahead() -> None:
    found = danger_points(None, snap(0, {"A": (5600, 5500), "B": (5800, 5600)}), GEO)
    assert kinds(found) == ["train_rear"] and found[0].where == "A->B"
    assert danger_points(None, snap(0, {"A": (5590, 5490), "B": (5800, 5600)}), GEO) == []


# ------------------------------------------------------------------------------------------ 3


def moving(target: str) -> MachineState:
    return MachineState(None, target, True)


def test_a_point_moving_under_a_train() -> None:
    st = station(machines={"31": moving("reverse")})
    found = point_safety(None, snap(0, {"A": (6050, 5950)}, st), GEO)
    assert kinds(found) == ["point_moved_under_train"] and found[0].where == "20/31"
    assert point_safety(None, snap(0, {"A": (5950, 5850)}, st), GEO) == []


def test_a_point_moving_while_a_locked_route_holds_it_but_not_while_its_route_is_set() -> None:
    for status in ("set", "entered", "cancelling"):
        st = station({"0111": status}, {"0111": ROUTE_0111}, {"31": moving("reverse")})
        assert kinds(point_safety(None, snap(0, {}, st), GEO)) == ["point_moved_locked"]
    setting = station({"0111": "setting"}, {"0111": ROUTE_0111}, {"31": moving("normal")})
    assert point_safety(None, snap(0, {}, setting), GEO) == []


def test_a_train_onto_a_point_lying_wrong_or_moving() -> None:
    held = {"0111": ROUTE_0111}
    right = station({"0111": "set"}, held)
    wrong = station({"0111": "set"}, held, {"31": MachineState("reverse", "reverse", False)})
    between = replace(right, machines=AT_REST | {"31": moving("normal")})
    a, b = {"A": (5990, 5890)}, {"A": (6010, 5910)}
    assert point_safety(snap(0, a, right), snap(1, b, right), GEO) == []
    found = point_safety(snap(0, a, wrong), snap(1, b, wrong), GEO)
    assert kinds(found) == ["point_wrong_position"] and "needs normal" in found[0].text
    assert "point_not_lying" in kinds(point_safety(snap(0, a, between), snap(1, b, between), GEO))


# ------------------------------------------------------------------------------------------ 4


def indications() -> dict[int, int]:
    chart = station_chart(LINE.view(20), "ixl_to_ctc")
    return {c.number: 0 for c in chart.codes} | {1: 1}


def agreeing(**kw: object) -> StationState:
    chart = station_chart(LINE.view(20), "ixl_to_ctc")
    ind = indications()
    view = {chart.name_of(k) or str(k): v for k, v in ind.items()}
    base = station(indications=ind, ctc_view=view, ctc_known=True, occupied=frozenset({"TC2047"}))
    return replace(base, **kw)  # type: ignore[arg-type]


def test_settled_views_agree() -> None:
    assert views_agree(snap(0, {}, agreeing(), frozenset({"TC2047"})), GEO) == []


def test_a_ctc_view_that_differs_from_its_ixl() -> None:
    st = agreeing()
    assert st.ctc_view is not None
    name = next(iter(st.ctc_view))
    stale = replace(st, ctc_view={**st.ctc_view, name: 1 - st.ctc_view[name]})
    found = views_agree(snap(0, {}, stale, frozenset({"TC2047"})), GEO)
    assert kinds(found) == ["ctc_view"] and name in found[0].text
    unsynced = replace(st, ctc_known=False)
    assert kinds(views_agree(snap(0, {}, unsynced, frozenset({"TC2047"})), GEO)) == [
        "ctc_not_synced"
    ]


def test_an_ixl_occupancy_that_differs_from_the_rails() -> None:
    found = views_agree(snap(0, {}, agreeing(), frozenset({"TC2047", "TC2055"})), GEO)
    assert kinds(found) == ["occupancy"] and "TC2055" in found[0].text
    # a track circuit another station handles is not this IXL's to take
    assert views_agree(snap(0, {}, agreeing(), frozenset({"TC2047", "TC1851"})), GEO) == []


# ------------------------------------------------------------------------------------------ checker


def test_the_checker_keeps_history_between_looks() -> None:
    checker = SafetyChecker(LINE)
    assert checker.feed(snap(0, {"A": (5990, 5890)})) == []  # first look: nothing crossed yet
    found = checker.feed(snap(1, {"A": (6010, 5910)}))
    assert kinds(found) == ["danger_point"] and checker.violations == found
    assert str(found[0]).startswith("t=1.000 s invariant 2 (danger_point) at TC2053A")


# ------------------------------------------------------------------------------------------ replay files


def test_a_replay_file_round_trips_and_a_bad_one_is_a_clear_error(tmp_path: Path) -> None:
    steps = ({"do": "route", "station": 20, "entry": "01", "exit": "11", "action": "set",
              "run_s": 2.0}, {"do": "settle", "run_s": 10.0})  # fmt: skip
    replay = Replay("emulators/labs/safety.yaml", 7, 8.0, steps, ("t=1 s invariant 2 ...",))
    assert load_replay(replay.write(tmp_path / "r.json")) == replay
    for text, why in (
        ("{", "not JSON"),
        ("[]", "a JSON object"),
        ('{"lab": "x", "steps": [{"do": "fly"}]}', "each with do"),
        ('{"steps": []}', "lab, seed"),
    ):
        (tmp_path / "bad.json").write_text(text)
        with pytest.raises(ConfigError, match=why):
            load_replay(tmp_path / "bad.json")
    with pytest.raises(ConfigError, match="cannot read"):
        load_replay(tmp_path / "absent.json")


def test_the_start_up_lock_protects_the_ground_it_holds_but_is_no_route() -> None:
    """A restarted IXL's start-up lock (ixl.interlocking) holds ground a train may run onto
    (invariant 2); it is no route over a point, and a throw its predecessor began may finish
    under it (invariant 3 still forbids any throw under a train)."""
    st = replace(station(machines={"31": moving("reverse")}), startup_held=frozenset({"31"}))
    assert point_safety(None, snap(0, {}, st), GEO) == []
    assert kinds(point_safety(None, snap(0, {"A": (6050, 5950)}, st), GEO)) == [
        "point_moved_under_train"
    ]
    st = replace(station(), startup_held=frozenset({"TC2053A"}))
    assert (
        danger_points(snap(0, {"A": (5990, 5890)}, st), snap(1, {"A": (6010, 5910)}, st), GEO) == []
    )
