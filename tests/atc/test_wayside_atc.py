"""Track-circuit model and wayside ATC: occupancy from positions, codes from route state."""

from __future__ import annotations

import pytest

from ktcs_bench.atc import TrackCircuitModel, TrainPosition, WaysideAtc
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station import Line, load_line


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


def test_occupancy_from_positions_respects_station_tracks(line: Line) -> None:
    model = TrackCircuitModel(line)
    changes = model.update([TrainPosition("T1", head_m=6500, tail_m=6300, track="2")])
    assert changes == {"TC2056": True}
    # put somewhere else: taken off, then put on (a known train moves along its path instead)
    assert model.update([]) == {"TC2056": False}
    changes = model.update([TrainPosition("T1", head_m=6150, tail_m=5950, track="1")])
    assert changes == {"TC2047": True, "TC2053A": True, "TC2053B": True}
    assert model.under_antenna("T1") == "TC2053B"


def test_antenna_picks_the_track_circuit_ahead_at_a_joint(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.update([TrainPosition("up", 2000, 1800), TrainPosition("down", 2800, 3000)])
    assert model.under_antenna("up") == "TC1863"  # head on the joint, running up
    assert model.under_antenna("down") == "TC1863"  # head on the joint, running down


def test_track_circuit_faults(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.update([TrainPosition("T1", 2500, 2300)])
    assert model.fail("TC1863", "failed_clear") == {"TC1863": False}  # the wrong-side failure
    assert model.fail("TC1867", "failed_occupied") == {"TC1867": True}
    assert model.clear_fault() == {"TC1863": True, "TC1867": False}
    with pytest.raises(ValueError):
        model.fail("TC1863", "flooded")


def test_code_under_the_antenna_and_no_code_fault(line: Line) -> None:
    model = TrackCircuitModel(line)
    atc = WaysideAtc(line, 18)
    model.update([TrainPosition("T1", 2500, 2300)])
    atc.set_occupancy(model.occupancy(), 0.0)
    atc.link_state(True, 0.0)
    out = atc.receive({"TDU1820": 1, "TDD1820": 0}, 0.0)
    model.set_codes(atc.track_codes())
    assert "TC1863" in out.codes  # a direction gives the plain line its codes
    code = model.code_for("T1")
    assert code is not None and code == atc.track_codes()["TC1863"]
    model.fail("TC1863", "no_code")
    assert model.code_for("T1") is None


def _wired(line: Line, station: int) -> tuple[StationRig, WaysideAtc]:
    rig = StationRig(line.view(station))
    atc = WaysideAtc(line, station)
    atc.set_occupancy({t.name: False for t in line.all_track_circuits()}, 0.0)
    atc.link_state(True, 0.0)
    atc.receive(rig.atc, 0.0)
    return rig, atc


def test_most_restrictive_code_everywhere_on_communication_error(line: Line) -> None:
    rig, atc = _wired(line, 20)
    rig.control("RSC200111")
    rig.advance(5)
    atc.receive(rig.atc, 5.0)
    assert atc.track_codes()["TC2047"].target_speed_kmh > 0
    out = atc.link_state(False, 6.0)
    stop = line.most_restrictive_code
    codes = atc.track_codes()
    assert set(codes) == {t.name for t in line.view(20).track_circuits}
    for c in codes.values():
        assert (c.code, c.target_speed_kmh, c.target_distance_m) == (stop.code, 0.0, 0.0)
    assert out.codes and "communication error" in out.events[0].text


def test_codes_follow_route_state_and_occupancy(line: Line) -> None:
    rig, atc = _wired(line, 20)
    home_approach = atc.track_codes()["TC2047"]
    assert home_approach.target_speed_kmh == 0  # home signal 01 at stop ahead
    assert home_approach.target_distance_m == 800  # stop at the end of TC2047
    rig.control("RSC200111")
    rig.advance(5)
    out = atc.receive(rig.atc, 5.0)
    assert "TC2047" in out.codes
    c = atc.track_codes()["TC2047"]
    assert c.target_distance_m == 800 + 100 + 100 + 600  # to starting signal 11
    assert c.target_speed_kmh > 0
    rig.control("RSC201191")  # run through: the path goes on into interval 2022
    rig.advance(5)
    atc.receive(rig.atc, 10.0)
    assert atc.track_codes()["TC2047"].target_distance_m == 1600 + 200 + 5000
    atc.set_occupancy({"TC2063": True}, 11.0)  # a train ahead in the interval
    assert atc.track_codes()["TC2047"].target_distance_m == 1600 + 200 + 800
    assert atc.track_codes()["TC2061A"].target_speed_kmh == 0  # next one occupied
    atc.set_occupancy({"TC2055": True}, 12.0)
    assert atc.track_codes()["TC2053B"].target_distance_m == 100  # rear of the occupied berth


def test_path_survives_the_signal_going_back_to_stop(line: Line) -> None:
    rig, atc = _wired(line, 20)
    rig.control("RSC200111")
    rig.advance(5)
    atc.receive(rig.atc, 5.0)
    rig.occupy("TC2053A")  # the train enters: signal 01 to stop, RLI drops
    atc.receive(rig.atc, 6.0)
    atc.set_occupancy({"TC2053A": True}, 6.0)
    assert rig.atc["RLI200111"] == 0
    code = atc.track_codes()["TC2053A"]
    assert code.target_distance_m == 100 + 100 + 600  # still guided to signal 11


def test_gradient_sign_follows_the_direction_of_travel(line: Line) -> None:
    atc = WaysideAtc(line, 20)
    atc.set_occupancy({t.name: False for t in line.all_track_circuits()}, 0.0)
    atc.link_state(True, 0.0)
    atc.receive({"TDU2022": 1, "TDD2022": 0}, 0.0)
    assert atc.track_codes()["TC2063"].gradient_permille == 15  # climbing up
    atc.receive({"TDU2022": 0, "TDD2022": 1}, 0.0)
    assert atc.track_codes()["TC2063"].gradient_permille == -15  # descending down


def test_target_speed_is_graded_by_braking_distance(line: Line) -> None:
    atc = WaysideAtc(line, 20)
    atc.set_occupancy({t.name: False for t in line.all_track_circuits()}, 0.0)
    atc.link_state(True, 0.0)
    atc.receive({"TDU1820": 1, "TDD1820": 0}, 0.0)
    speeds = [atc.track_codes()[t].target_speed_kmh for t in ("TC2043", "TC2045", "TC2047")]
    assert speeds == [110, 80, 0]  # 80: the next track circuit's limit; 0: home at stop
    atc.set_occupancy({"TC2047": True}, 1.0)
    assert atc.track_codes()["TC2045"].target_speed_kmh == 0
    # braking over TC2045 to its exit: 88 km/h in 800 m at 0.5 m/s² less the 0.12 m/s² the
    # −12 ‰ descent takes off it, after 1 s of brake build-up (on the level: 102 km/h, code 90)
    assert atc.track_codes()["TC2043"].target_speed_kmh == 80
    assert {c.code for c in atc.track_codes().values()} <= {c.code for c in line.speed_codes}


def test_occupancy_codes_for_the_ixl(line: Line) -> None:
    atc = WaysideAtc(line, 18)
    assert all(v == 1 for v in atc.full_state().values())  # unknown = occupied
    out = atc.set_occupancy({t.name: False for t in line.all_track_circuits()}, 0.0)
    assert all(v == 0 for _, v in out.ixl)
    out = atc.set_occupancy({"TC2045": True}, 1.0)  # station 20's half of interval 1820
    assert dict(out.ixl) == {"IZC1820": 1}
    out = atc.set_occupancy({"TC1863": True}, 2.0)
    assert dict(out.ixl) == {"TC1863": 1, "TTC1861A1867": 1}


def test_unknown_ixl_code_is_logged(line: Line) -> None:
    atc = WaysideAtc(line, 22)
    out = atc.receive({"RLI229999": 1}, 0.0)
    assert "unknown code" in out.events[0].text


def test_rails_lost_every_track_circuit_occupied_and_most_restrictive(line: Line) -> None:
    rig, atc = _wired(line, 20)
    rig.control("RSC200111")
    rig.advance(5)
    atc.receive(rig.atc, 5.0)
    assert atc.track_codes()["TC2047"].target_speed_kmh > 0
    assert not any(atc.full_state().values())
    out = atc.rails_state(False, 6.0)
    assert dict(out.ixl) == dict.fromkeys(atc.full_state(), 1)  # TC, TTC, IZC: all occupied
    stop = line.most_restrictive_code
    for c in atc.track_codes().values():
        assert (c.code, c.target_speed_kmh, c.target_distance_m) == (stop.code, 0.0, 0.0)
    assert out.codes and any("rails lost" in e.text for e in out.events)
    clear = {t.name: False for t in line.all_track_circuits()}
    assert atc.set_occupancy(clear, 7.0).ixl == []  # a lost source reports nothing
    assert atc.rails_state(True, 8.0).ixl == []  # back, but nothing reported yet
    out = atc.set_occupancy(clear, 9.0)
    assert dict(out.ixl) == dict.fromkeys(atc.full_state(), 0)
    assert atc.track_codes()["TC2047"].target_speed_kmh > 0


def test_a_diverging_route_limits_the_speed_at_the_exit_of_its_approach(line: Line) -> None:
    """A code's speed is the speed at its track circuit's exit: on the approach to a route with
    its own limit (01 -> 12 into the loop, 45 km/h), the train must be down to that limit where
    it enters the route, not only once inside it."""
    rig, atc = _wired(line, 18)
    limit = line.view(18).station.route("0112").speed_limit_kmh
    assert limit == 45
    assert rig.control("RSC180112").accepted
    rig.advance(10)
    atc.receive(rig.atc, 10.0)
    assert rig.atc["RLI180112"] == 1
    codes = atc.track_codes()
    assert 0 < codes["TC1851"].target_speed_kmh <= limit  # the approach: down to 45 at its exit
    assert 0 < codes["TC1853A"].target_speed_kmh <= limit  # inside the route
