"""Trackside I/O: point throws and indications, lamp fall-back, track relays, faults, link loss."""

from __future__ import annotations

import pytest

from ktcs_bench.field import Trackside
from ktcs_bench.station import Line, load_line


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


@pytest.fixture()
def io(line: Line) -> Trackside:
    t = Trackside(line.view(18))
    t.link_state(True, 0.0)
    return t


def test_initial_state_points_normal_signals_red_track_clear(io: Trackside) -> None:
    s = io.full_state()
    assert (s["SNI1831"], s["SRN1831"], s["SRI1831"], s["SNR1831"]) == (1, 0, 0, 0)
    assert s["LPS1801R"] == 1 and s["LPS1801G"] == 0 and s["LFI1801"] == 0
    assert s["TC1855"] == 0
    assert set(s) == set(io.full_state())  # stable keys


def test_point_throw_takes_throw_time_and_shows_moving(io: Trackside) -> None:
    out = io.receive({"PNC1831": 0, "PRC1831": 1}, 10.0)  # a call: answered with all four
    assert dict(out.changes) == {"SNI1831": 0, "SRN1831": 0, "SRI1831": 0, "SNR1831": 1}
    assert io.next_deadline() == 14.0
    assert io.handle_timer(13.9).changes == []
    out = io.handle_timer(14.0)
    assert dict(out.changes) == {"SNR1831": 0, "SRI1831": 1}
    assert io.next_deadline() is None
    out = io.receive({"PRC1831": 0, "PNC1831": 1}, 20.0)
    assert dict(out.changes) == {"SNI1831": 0, "SRN1831": 1, "SRI1831": 0, "SNR1831": 0}


def test_every_call_is_answered_with_the_point_s_indications_changed_or_not(
    io: Trackside,
) -> None:
    """The interlocking believes a detection only once the trackside has answered its call
    (`ixl.points`): a call of the position the blades already lie in is answered too, with the
    indications unchanged -- and with what detection says, right or wrong (a crossed fault)."""
    out = io.receive({"PNC1831": 1, "PRC1831": 0}, 0.0)
    assert out.changes == [("SNI1831", 1), ("SRN1831", 0), ("SRI1831", 0), ("SNR1831", 0)]
    io.fail_point("32", "crossed", 0.0)
    out = io.receive({"PNC1832": 0, "PRC1832": 1}, 1.0)  # lying normal, reported reverse
    assert dict(out.changes) == {"SNI1832": 0, "SRN1832": 0, "SRI1832": 0, "SNR1832": 1}
    assert io.receive({"SGC1801R": 1}, 2.0).changes == []  # no call, no answer


def test_throw_reversed_half_way_comes_back_in_the_time_it_ran(io: Trackside) -> None:
    io.receive({"PNC1832": 0, "PRC1832": 1}, 0.0)
    io.handle_timer(1.0)
    io.receive({"PNC1832": 1, "PRC1832": 0}, 1.0)
    assert io.next_deadline() == pytest.approx(2.0)
    assert dict(io.handle_timer(2.0).changes) == {"SRN1832": 0, "SNI1832": 1}


def test_no_demand_or_both_demands_leave_the_point_alone(io: Trackside) -> None:
    assert io.receive({"PNC1831": 1, "PRC1831": 1}, 0.0).changes == []
    assert io.receive({"PNC1831": 0, "PRC1831": 0}, 0.0).changes == []
    assert io.points["31"].position == "normal"


def test_detection_fault_and_jam(io: Trackside) -> None:
    out = io.fail_point("31", "detection", 0.0)
    assert dict(out.changes) == {"SNI1831": 0}
    io.clear_faults(0.0)
    io.fail_point("32", "jammed", 0.0)
    io.receive({"PNC1832": 0, "PRC1832": 1}, 0.0)
    assert io.next_deadline() is None
    io.handle_timer(100.0)
    s = io.full_state()
    assert s["SNR1832"] == 1 and s["SRI1832"] == 0  # never arrives
    with pytest.raises(ValueError):
        io.fail_point("31", "melted", 0.0)


def test_signal_lights_the_commanded_aspect(io: Trackside) -> None:
    out = io.receive({"SGC1801R": 0, "SGC1801G": 1}, 0.0)
    assert dict(out.changes) == {"LPS1801R": 0, "LPS1801G": 1}
    out = io.receive({"SGC1801G": 1, "SGC1801Y": 1}, 0.0)  # two at once: most restrictive
    assert dict(out.changes) == {"LPS1801G": 0, "LPS1801R": 1}


def test_lamp_failure_falls_back_to_a_more_restrictive_aspect(io: Trackside) -> None:
    io.receive({"SGC1801R": 0, "SGC1801G": 1}, 0.0)
    out = io.fail_lamp("01", "G", 0.0)
    assert dict(out.changes) == {"LPS1801G": 0, "LPS1801YG": 1, "LFI1801": 1}
    io.fail_lamp("01", "YG", 0.0)
    assert io.full_state()["LPS1801Y"] == 1
    io.fail_lamp("01", "Y", 0.0)
    assert io.full_state()["LPS1801R"] == 1
    out = io.fail_lamp("01", "R", 0.0)
    assert dict(out.changes) == {"LPS1801R": 0}  # dark, failure still reported
    assert io.signals["01"].lit() is None


def test_track_relays_follow_trains_and_faults(io: Trackside) -> None:
    assert dict(io.set_occupancy({"TC1855": True}, 0.0).changes) == {"TC1855": 1}
    assert dict(io.fail_track_circuit("TC1855", "failed_clear", 0.0).changes) == {"TC1855": 0}
    assert dict(io.fail_track_circuit("TC1856", "failed_occupied", 0.0).changes) == {"TC1856": 1}
    out = io.clear_faults(0.0)
    assert dict(out.changes) == {"TC1855": 1, "TC1856": 0}


def test_link_loss_puts_every_signal_to_stop(io: Trackside) -> None:
    io.receive({"SGC1811R": 0, "SGC1811G": 1}, 0.0)
    assert io.full_state()["LPS1811G"] == 1
    out = io.link_state(False, 1.0)
    assert dict(out.changes) == {"LPS1811G": 0, "LPS1811R": 1}
    assert any("communication error" in e.text for e in out.events)
    out = io.link_state(True, 2.0)
    assert dict(out.changes) == {"LPS1811R": 0, "LPS1811G": 1}  # commands still held


def test_unknown_command_is_logged_and_ignored(io: Trackside) -> None:
    out = io.receive({"XYZ1801": 1}, 0.0)
    assert out.changes == [] and "unknown command" in out.events[0].text


def test_rails_lost_every_track_relay_occupied_until_reported_again(io: Trackside) -> None:
    tcs = sorted(io.relays)
    io.set_occupancy(dict.fromkeys(tcs, False), 0.0)
    io.set_occupancy({"TC1855": True}, 0.0)
    io.fail_track_circuit("TC1856", "failed_clear", 0.0)  # even a relay stuck up
    out = io.rails_state(False, 1.0)
    assert dict(out.changes) == {t: 1 for t in tcs if t != "TC1855"}
    assert any("rails lost" in e.text for e in out.events)
    assert io.set_occupancy(dict.fromkeys(tcs, False), 2.0).changes == []  # a lost source
    out = io.rails_state(True, 3.0)  # back, but nothing reported yet: only the relay stuck up
    assert out.changes == [("TC1856", 0)]  # shows its injected wrong-side failure again
    out = io.set_occupancy(dict.fromkeys(tcs, False), 4.0)
    assert dict(out.changes) == {t: 0 for t in tcs if t != "TC1856"}
    assert all(io.full_state()[t] == 0 for t in tcs)


def test_blades_where_the_machine_has_them_moving_included(io: Trackside) -> None:
    assert io.blades() == {"31": "normal", "32": "normal"}
    io.receive({"PNC1831": 0, "PRC1831": 1}, 0.0)
    assert io.blades()["31"] == "moving"
    io.handle_timer(4.0)
    assert io.blades()["31"] == "reverse"
    io.fail_point("32", "jammed", 5.0)
    io.receive({"PNC1832": 0, "PRC1832": 1}, 5.0)
    io.handle_timer(20.0)
    assert io.blades()["32"] == "moving"  # jammed: never arrives


def test_a_trailed_point_loses_its_detection_until_a_fault_clear(io: Trackside) -> None:
    out = io.trail("31", "reverse", 1.0)  # a train ran through from the reverse leg
    assert dict(out.changes) == {"SNI1831": 0}  # no indication at all
    assert io.blades()["31"] == "reverse"  # the blades forced over
    assert any("trailed" in e.text for e in out.events)
    assert io.handle_timer(30.0).changes == []  # stays lost
    out = io.clear_faults(31.0)
    assert dict(out.changes) == {"SRI1831": 1}  # repaired: detected where the blades lie
    with pytest.raises(ValueError):
        io.trail("31", "sideways", 32.0)
