"""Automatic route setting in virtual time, against the real interlocking cores of the reference
line (one per station, with its trackside) and the CTC's model of what they indicate: no sockets,
no clock. The tests step the occupancy as a train would (`ars_rig`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from ktcs_bench.ctc.ars import RETRY_S
from ktcs_bench.ixl.routes import RouteStatus
from ktcs_bench.station.timetable import Entry, Timetable, load_timetable

from .ars_rig import LINE, TIMETABLE, UP_MAIN, ArsLine, RailTrain, Railway, reference_text


def with_trains(*changes: dict[str, object]) -> Timetable:
    """The reference timetable with its trains' fields changed (one mapping per train)."""
    trains = tuple(
        dataclasses.replace(t, **c)  # type: ignore[arg-type]
        for t, c in zip(TIMETABLE.trains, changes, strict=False)
    )
    return dataclasses.replace(TIMETABLE, trains=trains)


def test_a_train_approaching_18_gets_its_home_route_requested_and_set() -> None:
    b = ArsLine()
    assert b.requested() == []  # an empty line: nothing to do
    b.occupy("TC1851")  # train 1001 comes onto the line before signal 01 of station 18
    assert b.requested("1001") == [(18, "0111")]
    assert b.sent[0].result.accepted and b.sent[0].before is RouteStatus.IDLE
    b.advance(10.0)
    assert b.status(18, "0111") is RouteStatus.SET
    assert b.aspect(18, "01") != "R"  # the train has its signal
    assert "train 1001: requests route 01-11 at station 18" in b.log_text()
    assert "train 1001: route 01-11 at station 18 accepted" in b.log_text()
    b.advance(60.0)
    assert b.requested() == [(18, "0111")]  # asked once


def test_a_conflicting_set_route_is_not_requested_and_the_log_says_why() -> None:
    b = ArsLine()
    assert b.operator(18, "RSC180221").accepted  # by hand: 02 -> track 1, against 01 -> 11
    b.occupy("TC1851")
    b.advance(30.0)
    assert b.requested() == []
    assert b.waiting("1001") == "conflicts with route 02-21 (set)"
    assert "train 1001 waits for route 01-11 at station 18: conflicts with route 02-21" in (
        b.log_text()
    )
    assert b.operator(18, "RCC180221").accepted  # the operator gives way
    assert b.requested() == [(18, "0111")]
    assert all(s.result.accepted for s in b.sent)


def test_of_two_conflicting_routes_due_at_once_one_is_asked_the_other_waits(
    tmp_path: Path,
) -> None:
    text = (
        reference_text()
        + """
  - id: "1002"
    train: seed001-table1
    direction: down
    enters: {track_circuit: TC1861A, at_s: 0}
    stops:
      - {station: 18, track: "2", stop_m: 620, dwell_s: 30}
"""
    )
    (tmp_path / "both.yaml").write_text(text, encoding="utf-8")
    b = ArsLine(on=(), timetable=load_timetable(tmp_path / "both.yaml", LINE))
    b.occupy("TC1851", "TC1861A")  # 1001 up before signal 01, 1002 down before signal 02
    b.advance(10.0)
    b.ars.switch(18, True, b.now)
    b.update()  # both due in the same instant: 01-11 and 02-22 conflict
    assert len(b.requested()) == 1 and all(s.result.accepted for s in b.sent)
    ((station, route),) = b.requested()
    other = "1002" if b.sent[0].request.train == "1001" else "1001"
    text = {"0111": "01-11", "0222": "02-22"}[route]
    assert b.waiting(other) == f"conflicts with route {text} (asked for)"
    b.update()
    assert b.waiting(other) == f"conflicts with route {text} (set)"


def test_an_occupied_route_is_not_requested_and_the_log_says_why() -> None:
    b = ArsLine()
    b.occupy("TC1855")  # something stands on track 1 at 18 (no train the describer knows)
    assert "TC1855 occupied: no train described there" in b.log_text()
    b.occupy("TC1851")
    b.advance(30.0)
    assert b.requested() == []
    assert b.waiting("1001") == "TC1855 occupied"
    assert "train 1001 waits for route 01-11 at station 18: TC1855 occupied" in b.log_text()
    b.clear("TC1855")
    assert b.requested() == [(18, "0111")]


def test_ars_off_at_a_station_requests_nothing_there_and_the_log_says_so() -> None:
    b = ArsLine(on=(18, 22))
    rail = Railway(b, [RailTrain("1001", list(UP_MAIN))])
    while "TC2047" not in (rail.trains[0].footprint or []):
        rail.tick()
        assert b.now < 600
    b.advance(120.0)
    assert (20, "0111") not in b.requested()
    assert b.waiting("1001") == "ARS off at station 20"
    assert "train 1001 waits for route 01-11 at station 20: ARS off at station 20" in b.log_text()
    b.ars.switch(20, True, b.now)
    assert "ARS on at station 20" in b.log_text()
    b.update()
    assert b.requested()[-1] == (20, "0111")


def test_the_starting_route_is_requested_when_the_dwell_is_over() -> None:
    b = ArsLine()
    b.occupy("TC1851")
    b.advance(5.0)
    b.move("TC1851", "TC1853A")
    b.move("TC1853A", "TC1855")  # wholly on track 1's circuit: arrived, the dwell starts
    arrived = b.now
    b.advance(30.0 - 0.5)  # the timetable's dwell is 30 s
    assert b.requested() == [(18, "0111")]
    assert b.waiting("1001") == f"dwell until {arrived + 30.0:.1f} s"
    b.advance(1.0)
    assert b.requested() == [(18, "0111"), (18, "1191")]
    assert b.sent[-1].time == pytest.approx(arrived + 30.0)  # at the deadline, not a poll later
    b.advance(10.0)
    assert b.status(18, "1191") is RouteStatus.SET and b.aspect(18, "11") != "R"


def test_a_train_not_yet_due_waits_for_its_time() -> None:
    b = ArsLine(timetable=with_trains({"enters": Entry("TC1851", 100.0)}))
    b.occupy("TC1851")
    b.advance(99.0)
    assert b.requested() == []
    assert b.waiting("1001") == "not due until 100.0 s"
    b.advance(1.0)
    assert b.requested() == [(18, "0111")]


def test_a_departure_time_holds_the_starting_route_past_the_dwell() -> None:
    b = ArsLine(timetable=with_trains({"depart_s": 200.0}))
    b.occupy("TC1851")
    b.move("TC1851", "TC1853A")
    b.move("TC1853A", "TC1855")
    b.advance(100.0)  # the dwell is long over
    assert b.requested() == [(18, "0111")]
    assert b.waiting("1001") == "not due until 200.0 s"
    b.advance(100.0)
    assert b.requested() == [(18, "0111"), (18, "1191")]


def test_a_station_in_local_mode_is_left_alone() -> None:
    b = ArsLine()
    b.rig(18).take(b.rigs[18].ixl.local("take", b.now))  # the local operator takes over
    b.occupy("TC1851")
    b.advance(20.0)
    assert b.requested() == []
    assert b.waiting("1001") == "station 18 in local mode"


def test_a_rejected_request_is_asked_again_later_not_at_once() -> None:
    b = ArsLine(on=())
    b.occupy("TC1851")
    b.hold = True  # the CTC's tables lag behind: what happens next it has not seen
    b.rigs[18].occupy("TC1853A")
    b.ars.switch(18, True, b.now)
    b.update()
    t0 = b.now
    assert [(s.request.route, s.result.accepted) for s in b.sent] == [("0111", False)]
    assert "train 1001: route 01-11 at station 18 not set: track occupied" in b.log_text()
    b.rigs[18].occupy("TC1853A", False)
    b.hold = False
    b.update()
    assert len(b.sent) == 1  # not at once
    assert b.waiting("1001") == f"not set (track occupied), asking again at {t0 + RETRY_S:.1f} s"
    b.advance(RETRY_S + 1.0)
    assert [(s.request.route, s.result.accepted) for s in b.sent] == [
        ("0111", False),
        ("0111", True),
    ]
    assert b.sent[-1].time == pytest.approx(t0 + RETRY_S)


def test_two_trains_run_the_timetable_each_route_asked_once_and_taken() -> None:
    """The reference timetable end to end: 1001 then 1003, 18 -> 20 -> 22, platform stops; 1003
    gets into station 22's loop while 1001 stands terminated in the main-track route. (These
    rails carry the up trains only: the timetable's down train 2001 never comes on, and ARS
    says it has not seen it; the crossing is tests/ctc/test_ars_direction.py's and the lab's.)"""
    b = ArsLine()
    path_1003 = [*UP_MAIN[:-1], "TC2256"]  # 1003 ends on track 2 at station 22
    rail = Railway(b, [RailTrain("1001", list(UP_MAIN), 0.0), RailTrain("1003", path_1003, 120.0)])
    rail.run(until=3600.0)
    assert all(t.done for t in rail.trains), [(t.id, t.footprint) for t in rail.trains]
    plan = [(18, "0111"), (18, "1191"), (20, "0111"), (20, "1191")]
    assert b.requested("1001") == [*plan, (22, "0111")]
    assert b.requested("1003") == [*plan, (22, "0112")]
    assert all(s.result.accepted and s.before is RouteStatus.IDLE for s in b.sent)
    states = {t["train"]: t["state"] for t in b.ars.status()["trains"]}
    assert states == {
        "1001": "terminated at station 22 track 1",
        "1003": "terminated at station 22 track 2",
        "2001": "not yet seen (expected at TC2261)",
    }
    # each starting route was asked for a full dwell (30 s) after the train stood on its platform
    arrived = {
        (e["train"], e["station"]): e["time"] for e in b.ars.log if " arrived at " in e["text"]
    }
    for s in b.sent:
        if s.request.route == "1191":
            assert s.time == pytest.approx(arrived[(s.request.train, s.request.station)] + 30.0)


def test_a_close_follower_waits_for_the_train_ahead() -> None:
    b = ArsLine(timetable=with_trains({}, {"enters": Entry("TC1851", 10.0)}))
    path_1003 = [*UP_MAIN[:-1], "TC2256"]
    rail = Railway(b, [RailTrain("1001", list(UP_MAIN), 0.0), RailTrain("1003", path_1003, 10.0)])
    rail.run(until=3600.0)
    assert all(t.done for t in rail.trains)
    assert all(s.result.accepted and s.before is RouteStatus.IDLE for s in b.sent)
    assert len(b.requested("1003")) == len(set(b.requested("1003"))) == 5
    waits = [e["text"] for e in b.ars.log if e["train"] == "1003" and " waits " in e["text"]]
    assert (
        "train 1003 waits for route 01-11 at station 18: route 01-11 still set, train 1001 in it"
        in waits
    ), waits


def test_a_train_stopped_on_another_track_leaves_from_the_track_it_is_on() -> None:
    b = ArsLine(on=())  # the operator routes 1001 into the loop by hand
    b.occupy("TC1851")
    assert b.operator(18, "RSC180112").accepted
    b.advance(10.0)
    b.move("TC1851", "TC1853A")
    b.move("TC1853A", "TC1856")
    assert "train 1001 arrived at station 18 track 2 (timetabled: track 1)" in b.log_text()
    b.ars.switch(18, True, b.now)
    b.advance(31.0)
    assert b.requested() == [(18, "1291")]  # 12 -> 91: out of the loop it stands in


def test_the_describer_loses_a_train_and_finds_it_again() -> None:
    b = ArsLine()
    b.occupy("TC1851")
    b.clear("TC1851")  # its circuit drops (a flicker)
    assert "train 1001 lost at TC1851" in b.log_text()
    assert b.waiting("1001") == "lost at TC1851"
    b.occupy("TC1853A")  # the circuit ahead occupies: that is the train
    assert "train 1001 found again at TC1853A" in b.log_text()


def test_a_station_showing_every_circuit_occupied_is_read_as_not_known_not_as_trains() -> None:
    b = ArsLine()
    own = [tc for tc, st in b.owner.items() if st == 18]
    b.link(18, False)
    b.occupy(*own)  # station 18's fail-safe picture: its ATC not yet reporting
    b.link(18, True)
    assert b.ars.describer.trains == {} and b.requested() == []
    b.clear(*[tc for tc in own if tc != "TC1851"])  # its ATC reports: a train stands on TC1851
    assert "train 1001 identified at TC1851" in b.log_text()
    assert b.requested("1001") == [(18, "0111")]
    b.occupy(*own)  # its ATC link drops: every circuit occupied again
    assert b.ars.describer.trains["1001"].footprint == ["TC1851"]  # the train stays where it was
    assert b.waiting("1001") is None


def test_a_train_leaving_the_lab_is_no_longer_described(tmp_path: Path) -> None:
    text = reference_text().replace(
        "    stops:\n      - {station: 18",
        "    leaves_lab: true\n    stops:\n      - {station: 18",
        1,
    )
    (tmp_path / "leaving.yaml").write_text(text, encoding="utf-8")
    timetable = load_timetable(tmp_path / "leaving.yaml", LINE)
    assert timetable.trains[0].leaves_lab and timetable.trains[0].stops[-1].start_route == "1191"
    b = ArsLine(timetable=timetable)
    rail = Railway(b, [RailTrain("1001", [*UP_MAIN, "TC2257A", "TC2261"])])
    rail.run(until=1200.0)
    assert rail.trains[0].footprint == ["TC2261"]
    assert b.requested()[-1] == (22, "1191")
    b.clear("TC2261")  # off the end of the line
    assert "train 1001 left the lab at TC2261" in b.log_text()
    status = b.ars.status()
    assert status["gone"] == ["1001"]
    assert "1001" not in [t["train"] for t in status["trains"]]
