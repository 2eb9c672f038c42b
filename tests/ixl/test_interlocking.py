"""IXL behaviour on station 20 (three tracks, four points), wired straight to its trackside."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from ktcs_bench.atc.wayside import AtcOutput, WaysideAtc
from ktcs_bench.binding import ControlLink
from ktcs_bench.ixl import Interlocking, Mode, Reason, RouteStatus
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.stations import link_charts

from .direction_pair import Pair

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


@pytest.fixture()
def rig(line: Line) -> StationRig:
    return StationRig(line.view(20))


def test_reason_numbers_are_the_wire_values() -> None:
    assert [int(r) for r in Reason] == [0, 1, 2, 3, 4, 5, 6, 7]
    assert Reason.NOT_IN_CENTER_MODE == 1 and Reason.UNKNOWN_CODE == 6 and Reason.DIRECTION == 7
    profile = yaml.safe_load((ROOT / "protocols" / "type2.yaml").read_text(encoding="utf-8"))
    (result,) = [op for op in profile["opcodes"] if op.get("name") == "CONTROL_RESULT"]
    assert result["reasons"] == {int(r): r.text for r in Reason}  # the wire names them alike


@pytest.mark.requirement("IXL-ROUTE-01")
def test_route_set_throws_points_awaits_detection_then_clears(rig: StationRig) -> None:
    result = rig.control("RSC200112")
    assert result.accepted and result.reason is Reason.NONE and result.name == "RSC200112"
    assert rig.ixl.route_status("0112") is RouteStatus.SETTING
    assert rig.ixl.aspect("01") == "R"
    assert rig.ixl.full_state("io")["PRC2031"] == 1  # point 31 commanded reverse
    assert rig.ctc["SNR2031"] == 1 and rig.ctc["SNI2031"] == 0  # moving normal -> reverse
    assert rig.ctc["SLI2031"] == 1 and rig.ctc["RSI200112"] == 1
    rig.advance(3.9)
    assert rig.ixl.aspect("01") == "R"  # throw time 4 s not yet over
    rig.advance(0.2)
    assert rig.ixl.route_status("0112") is RouteStatus.SET
    assert rig.ctc["SRI2031"] == 1 and rig.ctc["SRI2032"] == 1  # overlap point 32 too
    assert rig.ixl.aspect("01") == "Y"  # diverging route, exit signal at stop
    assert rig.ctc["ASP2001Y"] == 1 and rig.ctc["ASP2001R"] == 0  # proved by the lamps
    assert rig.atc["RLI200112"] == 1 and rig.atc["SGP2001"] == 1


def test_main_route_aspect_follows_the_exit_signal(rig: StationRig) -> None:
    rig.control("RSC200111")
    rig.advance(5)
    assert rig.ixl.aspect("01") == "Y"
    assert rig.control("RSC201191").accepted  # run-through: takes over the overlap
    rig.advance(5)
    assert rig.ixl.aspect("11") == "G" and rig.ixl.aspect("01") == "G"
    assert "TC2057B" in rig.ixl.routes["1191"].held_tcs
    assert "TC2057B" not in rig.ixl.routes["0111"].held_tcs
    rig.control("RCC201191")
    assert rig.ixl.route_status("1191") is RouteStatus.IDLE
    assert "TC2057B" in rig.ixl.routes["0111"].held_tcs  # overlap locked again
    assert rig.ixl.aspect("01") == "Y"


@pytest.mark.requirement("IXL-ROUTE-02")
@pytest.mark.parametrize(
    ("setup", "control", "reason"),
    [
        ([], "RSC201391", Reason.NONE),
        (["RSC200111"], "RSC200221", Reason.ROUTE_CONFLICTS),  # opposing into track 1
        (["RSC200111"], "RSC200113", Reason.ROUTE_CONFLICTS),  # same entry signal
        (["RSC200112"], "SNC2031", Reason.POINT_LOCKED),
        ([], "SNC2099", Reason.UNKNOWN_CODE),
        ([], "ASP2001R", Reason.UNKNOWN_CODE),  # an indication is not a control
    ],
)
def test_rejection_reasons(rig: StationRig, setup: list[str], control: str, reason: Reason) -> None:
    for c in setup:
        assert rig.control(c).accepted
    result = rig.control(control)
    assert result.reason is reason and result.accepted is (reason is Reason.NONE)


def test_rejected_when_track_occupied(rig: StationRig) -> None:
    rig.occupy("TC2056")
    assert rig.control("RSC200112").reason is Reason.TRACK_OCCUPIED
    assert rig.control("SRC2033").accepted  # point 33 is elsewhere
    rig.occupy("TC2053A")
    assert rig.control("SRC2031").reason is Reason.TRACK_OCCUPIED  # occupied point


def test_rejected_when_point_failed(rig: StationRig) -> None:
    rig.from_field(rig.io.fail_point("32", "detection", rig.now).changes)
    assert rig.ctc["SFI2032"] == 1
    assert rig.control("RSC200112").reason is Reason.POINT_FAILED


def test_unknown_code_number(rig: StationRig) -> None:
    """Controls come by number (Type II): the IXL's binding refuses a number the chart lacks and
    hands a known one to the interlocking by name."""
    given: list[str] = []

    def control(name: str, value: int) -> tuple[bool, int]:
        given.append(name)
        result = rig.control(name, value)
        return result.accepted, int(result.reason)

    link = ControlLink(
        *link_charts(rig.view, "ixl_to_ctc"), lambda: rig.ctc, control, int(Reason.UNKNOWN_CODE)
    )
    assert link.on_control(9999, 1) == (False, Reason.UNKNOWN_CODE) and given == []
    assert link.control_name(21) == "RSC200112"
    assert link.on_control(link.rx.number_of("RSC200111"), 1) == (True, Reason.NONE)
    assert given == ["RSC200111"]
    assert rig.ixl.control("RSC209999", 1, rig.now).results[0].name is None  # not a control


@pytest.mark.requirement("IXL-MODE-01", "IXL-MODE-02")
def test_center_local_modes_and_cmr_handshake(line: Line) -> None:
    rig = StationRig(line.view(18), mode=Mode.LOCAL)
    assert (rig.ctc["LOC18"], rig.ctc["CTC18"], rig.ctc["CMR18"]) == (1, 0, 0)
    assert rig.control("RSC180111").reason is Reason.NOT_IN_CENTER_MODE
    assert rig.control("CMQ18").accepted
    assert (rig.ctc["LOC18"], rig.ctc["CTC18"], rig.ctc["CMR18"]) == (1, 0, 1)
    assert rig.control("RSC180111").reason is Reason.NOT_IN_CENTER_MODE  # not yet granted
    rig.take(rig.ixl.local("grant", rig.now))
    assert (rig.ctc["LOC18"], rig.ctc["CTC18"], rig.ctc["CMR18"]) == (0, 1, 0)
    assert rig.control("RSC180111").accepted
    local = rig.ixl.local_control("RCC180111", 1, rig.now)
    assert local.results[0].reason is Reason.NOT_IN_CENTER_MODE  # the local panel is locked out
    assert rig.control("LMQ18").accepted
    assert (rig.ctc["LOC18"], rig.ctc["CTC18"]) == (1, 0)
    rig.control("CMQ18")
    rig.take(rig.ixl.local("refuse", rig.now))
    assert (rig.ctc["LOC18"], rig.ctc["CTC18"], rig.ctc["CMR18"]) == (1, 0, 0)


def test_automatic_grant_keeps_cmr_visible(line: Line) -> None:
    ixl = Interlocking(line.view(22), auto_grant_s=1.0)
    out = ixl.control("CMQ22", 1, 10.0)
    assert ("CMR22", 1) in out.of("ctc") and ixl.next_deadline() == 11.0
    out = ixl.handle_timer(11.0)
    assert set(out.of("ctc")) >= {("CMR22", 0), ("CTC22", 1), ("LOC22", 0)}


def _run_train_into_track_2(rig: StationRig) -> None:
    rig.control("RSC200112")
    rig.advance(5)
    assert rig.ixl.aspect("01") == "Y"
    rig.occupy("TC2047")


@pytest.mark.requirement("IXL-ROUTE-03", "IXL-RELEASE-01")
def test_signal_to_stop_when_the_train_enters_then_sequential_release(rig: StationRig) -> None:
    _run_train_into_track_2(rig)
    rig.occupy("TC2053A")
    assert rig.ixl.aspect("01") == "R"
    assert rig.ixl.route_status("0112") is RouteStatus.ENTERED
    assert rig.atc["RLI200112"] == 0 and rig.ctc["RSI200112"] == 1
    rig.occupy("TC2047", False)
    rig.occupy("TC2053A", False)  # section 1 clear, but section 2 not yet entered: no release
    assert "TC2053A" in rig.ixl.routes["0112"].held_tcs
    rig.occupy("TC2053A")
    rig.occupy("TC2056")
    rig.occupy("TC2053A", False)
    rs = rig.ixl.routes["0112"]
    assert "TC2053A" not in rs.held_tcs and "31" not in rs.held_points
    assert rig.ctc["SLI2031"] == 0 and rig.ctc["SLI2032"] == 1  # overlap still locked
    assert rig.control("SNC2031").accepted  # released point may move again
    rig.advance(29)
    assert "32" in rs.held_points
    rig.advance(2)  # overlap timer: 30 s after the train reached the berth
    assert "32" not in rs.held_points and "TC2057A" not in rs.held_tcs
    assert rs.status is RouteStatus.ENTERED  # berth still held under the train
    rig.occupy("TC2056", False)
    assert rs.status is RouteStatus.IDLE and rig.ctc["RSI200112"] == 0


def test_the_overlap_timer_waits_while_no_train_movement_can_be_read(rig: StationRig) -> None:
    _run_train_into_track_2(rig)
    for tc, occupied in (("TC2053A", True), ("TC2056", True), ("TC2047", False)):
        rig.occupy(tc, occupied)
    rig.occupy("TC2053A", False)  # the train stands in the berth: the overlap timer runs
    rs = rig.ixl.routes["0112"]
    rig.set_link("atc", False)  # occupancy unknown: everything shows occupied
    rig.advance(60)  # past the 30 s -- the timer has nothing to do, so it is no deadline
    assert "32" in rs.held_points and rig.ixl.next_deadline() is None
    rig.set_link("atc", True)  # the ATC reports again: the time has run out
    assert "32" not in rs.held_points and "TC2057A" not in rs.held_tcs


@pytest.mark.requirement("IXL-LOCK-01")
def test_cancel_with_approach_locking_and_timed_release(rig: StationRig) -> None:
    _run_train_into_track_2(rig)  # train in the approach section, signal clear
    assert rig.control("RCC200112").accepted
    assert rig.ixl.aspect("01") == "R"
    assert rig.ixl.route_status("0112") is RouteStatus.CANCELLING
    assert rig.ctc["ALI200112"] == 1 and rig.ctc["RSI200112"] == 1
    assert rig.control("SNC2031").reason is Reason.POINT_LOCKED
    assert rig.control("RSC200112").reason is Reason.ROUTE_CONFLICTS
    assert rig.ixl.next_deadline() == pytest.approx(rig.now + 90)
    rig.advance(89)
    assert rig.ixl.route_status("0112") is RouteStatus.CANCELLING
    rig.advance(1.5)
    assert rig.ixl.route_status("0112") is RouteStatus.IDLE
    assert rig.ctc["ALI200112"] == 0 and rig.ctc["SLI2031"] == 0


@pytest.mark.requirement("IXL-ROUTE-04")
def test_cancel_without_approaching_train_releases_at_once(rig: StationRig) -> None:
    rig.control("RSC200112")
    rig.advance(5)
    assert rig.control("RCC200112").accepted
    assert rig.ixl.route_status("0112") is RouteStatus.IDLE and rig.ixl.aspect("01") == "R"


@pytest.mark.requirement("IXL-FAIL-01", "IXL-INV-04")
@pytest.mark.parametrize("fault", ["detection", "track", "atc_link", "io_link", "lamp_stop"])
def test_faults_put_the_signal_to_stop_at_once(rig: StationRig, fault: str) -> None:
    rig.control("RSC200113")
    rig.advance(5)
    assert rig.ixl.aspect("01") == "Y"
    if fault == "detection":
        rig.from_field(rig.io.fail_point("33", "detection", rig.now).changes)
        assert rig.ctc["SFI2033"] == 1
    elif fault == "track":
        rig.io.fail_track_circuit("TC2057B", "failed_occupied", rig.now)
        rig.occupy("TC2057B")  # as the ATC reports the failed (occupied) overlap
    elif fault == "atc_link":
        rig.set_link("atc", False)
        assert rig.ctc["TC2054"] == 1  # taken as occupied while the link is in error
    elif fault == "io_link":
        rig.set_link("io", False)
        assert rig.ctc["SFI2031"] == 1
    else:
        rig.control("SSC2001")
        assert rig.ctc["SSI2001"] == 1
    assert rig.ixl.aspect("01") == "R"
    assert rig.atc["SGP2001"] == 0 and rig.ixl.full_state("io")["SGC2001R"] == 1
    assert rig.ixl.route_status("0113") is RouteStatus.SET  # still locked, not entered
    # and the signal clears again once the fault is gone
    if fault == "detection":
        rig.from_field(rig.io.clear_faults(rig.now).changes)
    elif fault == "track":
        rig.occupy("TC2057B", False)
    elif fault in ("atc_link", "io_link"):
        rig.set_link(fault[:-5], True)
    else:
        rig.control("SSC2001", 0)
    assert rig.ixl.aspect("01") == "Y"


@pytest.mark.requirement("TS-SIGNAL-01")
def test_lamp_failure_is_reported_and_proved_aspect_indicated(rig: StationRig) -> None:
    rig.control("RSC200112")
    rig.advance(5)
    rig.from_field(rig.io.fail_lamp("01", "Y", rig.now).changes)
    assert rig.ctc["LFI2001"] == 1
    assert rig.ctc["ASP2001R"] == 1 and rig.ctc["ASP2001Y"] == 0  # head fell back to stop
    assert rig.atc["SGP2001"] == 0  # the ATC is not told proceed on an unproved lamp


@pytest.mark.requirement("IXL-POINT-01", "IXL-INV-02")
def test_point_control_only_when_free_and_unoccupied(rig: StationRig) -> None:
    assert rig.control("SRC2034").accepted
    assert rig.ctc["SNR2034"] == 1
    rig.advance(4)
    assert rig.ctc["SRI2034"] == 1
    rig.control("RSC200113")  # needs 34 reverse in its overlap: no move needed
    rig.advance(5)
    assert rig.control("SNC2034").reason is Reason.POINT_LOCKED
    assert rig.ixl.full_state("io")["PRC2034"] == 1


def test_without_its_neighbour_link_the_interval_is_worked_as_its_default_end_holds_it(
    rig: StationRig,
) -> None:
    """A station on the bench alone (no neighbour link): 1820's default direction is up, so
    station 18 holds it for good and station 20 (its far end) refuses down departures into it --
    it cannot ask anybody for the permission. Interval 2022, whose default end 20 is, departs."""
    assert rig.ctc["TDU1820"] == 1 and rig.ctc[n.phi("1820")] == 0
    assert rig.control("RSC202292").reason is Reason.DIRECTION  # down into 1820
    assert rig.ixl.route_status("2292") is RouteStatus.IDLE
    assert rig.ctc["TDU1820"] == 1 and rig.ctc["TDD1820"] == 0
    assert rig.ctc[n.phi("2022")] == 1
    assert rig.control("RSC201191").accepted  # up into 2022
    rig.advance(5)
    assert rig.ixl.aspect("11") == "G"


def test_occupied_with_signal_at_stop_does_not_count_as_entry(rig: StationRig) -> None:
    rig.control("RSC200112")
    rig.occupy("TC2053A")  # before the points are detected: signal never cleared
    rig.advance(5)
    assert rig.ixl.route_status("0112") is RouteStatus.SET
    assert rig.ixl.aspect("01") == "R"
    rig.occupy("TC2053A", False)
    assert rig.ixl.aspect("01") == "Y"  # a fault, not a train: the route stays set


@pytest.mark.requirement("IXL-FAIL-02", "IXL-START-01")
def test_links_start_down_and_everything_is_occupied(line: Line) -> None:
    ixl = Interlocking(line.view(18))
    state = ixl.full_state("ctc")
    assert state["TC1855"] == 1 and state["SFI1831"] == 1 and state["LOC18"] == 1
    assert all(v == 0 for k, v in ixl.full_state("atc").items() if k.startswith("SGP"))


def test_event_log_records_commands(rig: StationRig) -> None:
    rig.control("RSC200111")
    texts = [e.text for e in rig.events]
    assert "ctc: RSC200111=1 accepted" in texts and "route 0111 locked" in texts


def test_link_flap_during_a_train_movement_releases_nothing_ahead(rig: StationRig) -> None:
    rig.control("RSC200111")
    rig.advance(5)
    rig.occupy("TC2047")
    rig.occupy("TC2053A")
    assert rig.ixl.route_status("0111") is RouteStatus.ENTERED
    rig.set_link("atc", False)  # everything looks occupied while the link is in error
    rig.set_link("atc", True)
    rs = rig.ixl.routes["0111"]
    assert rs.passed == [True, False, False]
    rig.occupy("TC2053A", False)  # the train has not reached section 2: nothing may release
    assert {"TC2053A", "TC2053B", "TC2055"} <= rs.held_tcs


@pytest.mark.parametrize("link", ["atc", "io"])
def test_a_link_back_up_is_believed_only_for_what_it_reports_again(
    rig: StationRig, link: str
) -> None:
    rig.control("RSC200112")
    rig.advance(5)
    assert rig.ixl.aspect("01") == "Y"
    rig.take(rig.ixl.link_state(link, False, rig.now))
    if link == "io":
        rig.from_field(rig.io.link_state(False, rig.now).changes)
    assert rig.ixl.aspect("01") == "R"
    # the link is up again, but the peer's ALL_INFO has not arrived: what it said before the
    # outage may be out of date (a train may have come in), so nothing is read from it
    rig.take(rig.ixl.link_state(link, True, rig.now))
    assert rig.ixl.aspect("01") == "R"
    if link == "atc":
        assert rig.ctc["TC2053A"] == 1 and rig.ixl.occupied("TC2056")
    else:
        assert rig.ixl.detection("31") == "none" and rig.ctc["SFI2031"] == 1
    # the peer's full state arrives: the signal clears again
    if link == "atc":
        rig.occupy("TC2047", False)  # the ATC reports every track circuit
    else:
        rig.from_field(rig.io.link_state(True, rig.now).changes)
        rig.take(rig.ixl.receive("io", rig.io.full_state(), rig.now))
    assert rig.ixl.aspect("01") == "Y"


class AtcOnRails:
    """The station's wayside ATC as the IXL's source of occupancy, fed by the rails."""

    def __init__(self, rig: StationRig, line: Line) -> None:
        self.rig = rig
        self.atc = WaysideAtc(line, rig.view.number)
        self.tcs = [t.name for t in line.all_track_circuits()]
        self.atc.link_state(True, rig.now)
        self.atc.receive(rig.ixl.full_state("atc"), rig.now)
        self.report(self.atc.set_occupancy(dict.fromkeys(self.tcs, False), rig.now))

    def report(self, out: AtcOutput) -> None:
        """One ATC output is one CHANGE frame to the IXL: one input, all at once."""
        if out.ixl:
            self.rig.take(self.rig.ixl.receive("atc", dict(out.ixl), self.rig.now))

    def occupy(self, tc: str, occupied: bool = True) -> None:
        self.report(self.atc.set_occupancy({tc: occupied}, self.rig.now))

    def rails_lost(self) -> None:
        self.report(self.atc.rails_state(False, self.rig.now))

    def rails_back(self, occupied: tuple[str, ...] = ()) -> None:
        """The rails reconnect and report every track circuit (their full occupancy)."""
        self.report(self.atc.rails_state(True, self.rig.now))
        full = {tc: tc in occupied for tc in self.tcs}
        self.report(self.atc.set_occupancy(full, self.rig.now))


def _locked(rig: StationRig, route: str) -> bool:
    rs = rig.ixl.routes[route]
    r = rs.route
    return (
        set(r.all_track_circuits) <= rs.held_tcs
        and {s.point for s in r.all_points} <= rs.held_points
    )


def test_a_rails_outage_is_no_train_passage_the_route_stays_locked(
    rig: StationRig, line: Line
) -> None:
    atc = AtcOnRails(rig, line)
    rig.control("RSC200111")
    rig.advance(5)
    assert rig.ixl.aspect("01") == "Y"
    atc.rails_lost()  # every track circuit occupied in one report
    assert rig.ixl.aspect("01") == "R"
    assert rig.ixl.route_status("0111") is RouteStatus.ENTERED  # as if a train had entered
    rig.advance(60)  # longer than the overlap timer: no train reached the berth
    atc.rails_back()  # every track circuit clear in one report
    rig.advance(200)
    assert rig.ixl.route_status("0111") is RouteStatus.ENTERED and _locked(rig, "0111")
    assert all(rig.ctc[f"SLI20{p}"] == 1 for p in ("31", "33", "34"))  # points still locked
    assert rig.control("SNC2031").reason is Reason.POINT_LOCKED
    assert rig.ixl.aspect("01") == "R"
    # released properly: the operator cancels and the approach-locking time runs
    assert rig.control("RCC200111").accepted
    assert rig.ctc["ALI200111"] == 1
    rig.advance(89)
    assert _locked(rig, "0111")
    rig.advance(1.5)
    assert rig.ixl.route_status("0111") is RouteStatus.IDLE
    assert rig.ctc["SLI2031"] == 0 and rig.ctc["ALI200111"] == 0


def test_a_rails_outage_with_a_train_waiting_in_the_approach_releases_nothing(
    rig: StationRig, line: Line
) -> None:
    """A one-section departure route: its section and approach both occupied by the outage,
    then the section clear with the train still standing in the approach."""
    atc = AtcOnRails(rig, line)
    rig.control("RSC200112")
    rig.advance(5)
    atc.occupy("TC2047")
    atc.occupy("TC2053A")
    atc.occupy("TC2047", False)
    atc.occupy("TC2056")
    atc.occupy("TC2053A", False)  # a train in the berth of track 2
    assert rig.control("RSC201291").accepted  # its departure (takes over the overlap)
    rig.advance(5)
    assert rig.ixl.aspect("12") != "R"
    atc.rails_lost()
    atc.rails_back(occupied=("TC2056",))  # the train never moved
    rig.advance(120)
    assert rig.ixl.route_status("1291") is RouteStatus.ENTERED and _locked(rig, "1291")
    assert rig.ctc["SLI2032"] == 1


def test_a_failed_occupied_entry_section_that_recovers_releases_nothing(rig: StationRig) -> None:
    rig.control("RSC200111")
    rig.advance(5)
    rig.occupy("TC2053A")  # the first section fails occupied, no train in the approach
    assert rig.ixl.route_status("0111") is RouteStatus.ENTERED
    assert any("not a train's sequence" in e.text for e in rig.events)
    rig.occupy("TC2053B")
    rig.occupy("TC2053A", False)  # recovers; a later section flickers
    rig.occupy("TC2053B", False)
    rig.advance(100)
    assert _locked(rig, "0111")


def test_an_overlap_handed_on_is_locked_again_in_the_input_that_frees_it(line: Line) -> None:
    """The onward route that held our overlap is released: our overlap is locked again before
    anything else can use the gap (a point control in the very next input is refused)."""
    rig = StationRig(line.view(18))
    rig.control("RSC180112")
    rig.advance(5)
    for tc, occupied in [("TC1851", True), ("TC1853A", True), ("TC1851", False)]:
        rig.occupy(tc, occupied)
    rig.occupy("TC1856")
    rig.occupy("TC1853A", False)  # the train stands in the berth of track 2
    assert rig.control("RSC181291").accepted  # its departure takes over the overlap (point 32)
    rig.advance(5)
    assert "32" in rig.ixl.routes["1291"].held_points
    assert rig.control("RCC181291").accepted  # the train at signal 12: approach-locked
    due = rig.ixl.next_deadline()
    assert due is not None
    rig.now = due
    rig.take(rig.ixl.handle_timer(due))  # the one input in which 1291's timed release falls due
    assert rig.ixl.route_status("1291") is RouteStatus.IDLE
    assert "32" in rig.ixl.routes["0112"].held_points
    assert rig.control("SNC1832").reason is Reason.POINT_LOCKED


def test_an_interlocking_restarted_with_a_train_on_its_line_locks_the_station_for_a_while(
    line: Line,
) -> None:
    """Start-up locking. A restarted IXL knows nothing of the routes its predecessor had set, and
    a train may still be running on one, braking on the most restrictive code: the whole-system
    search (docs/system_safety.md) found a train's head run past a starting signal into a track
    circuit no route held any more, after its IXL restarted. So an IXL whose first live occupancy
    shows a train holds every point and track circuit for the longest approach-locking time."""
    rig = StationRig(line.view(20), occupied=("TC2047",), startup_locking=True)
    cold = StationRig(line.view(20), occupied=("TC2047",))  # a lab's start: the railway at rest
    assert not cold.ixl.startup_held and cold.control("RSC200111").accepted
    assert rig.ixl.startup_held == set(rig.occupancy) | set(rig.ixl.points)
    assert rig.control("SRC2031").reason is Reason.POINT_LOCKED
    assert rig.control("RSC200111").reason is Reason.ROUTE_CONFLICTS
    assert rig.control("RSC201191").reason is Reason.ROUTE_CONFLICTS
    assert rig.ctc["SLI2031"] == 1
    assert (rig.ixl.full_state("io")["PNC2031"], rig.ixl.full_state("io")["PRC2031"]) == (0, 0)
    rig.advance(89.5)
    assert rig.control("SRC2032").reason is Reason.POINT_LOCKED
    rig.advance(1.0)  # 90 s, the longest approach-locking time of station 20's routes
    assert not rig.ixl.startup_held and rig.ctc["SLI2031"] == 0
    assert rig.control("RSC200111").accepted
    assert any("start-up locking released (timed release)" in e.text for e in rig.events)


def test_an_interlocking_that_restarts_with_its_line_clear_is_free_at_once(line: Line) -> None:
    rig = StationRig(line.view(20), startup_locking=True)
    assert not rig.ixl.startup_held and rig.ixl.next_deadline() is None
    assert rig.control("SRC2031").accepted
    assert any("start-up locking released (the station is clear)" in e.text for e in rig.events)


@pytest.mark.requirement("IXL-INV-02")
def test_a_restarted_interlocking_demands_no_point_until_a_route_or_a_control_does(
    line: Line,
) -> None:
    """Seen while reading a failure of the whole-system search: a restarted IXL demanded every
    point normal (its default), so a point lying reverse was thrown back at once -- under a
    train standing on it, or a route its predecessor had locked. Demanding the position it
    reads instead threw the blades over under a train when detection lied (the next test).
    Restarted, it demands nothing of its own accord: a point is demanded by a route or a
    control, each with its checks."""
    ixl = Interlocking(line.view(20), mode=Mode.CENTER, startup_locking=True)
    io = ixl.full_state("io")
    assert (io["PNC2031"], io["PRC2031"]) == (0, 0)  # no demand: the machine stays put
    ixl.link_state("io", True, 0.0)
    ixl.link_state("atc", True, 0.0)
    bits = {
        f"{b}20{p.name}": 0 for p in line.station(20).points for b in ("SNI", "SRN", "SRI", "SNR")
    }
    bits |= {f"SNI20{p.name}": 1 for p in line.station(20).points} | {"SNI2031": 0, "SRI2031": 1}
    out = ixl.receive("io", bits, 1.0)
    assert not [c for c in out.of("io") if c[0].startswith(("PNC", "PRC"))], out.of("io")
    clear = {t.name: 0 for t in line.view(20).track_circuits}
    clear |= {n.izc(iv.name): 0 for iv in line.view(20).intervals}
    ixl.receive("atc", clear, 2.0)  # the station clear: start-up locking goes at once
    assert not ixl.startup_held
    assert ixl.full_state("io")["PRC2031"] == 0  # still nothing demanded
    assert ixl.control("SRC2031", 1, 3.0).results[0].accepted
    assert (ixl.full_state("io")["PNC2031"], ixl.full_state("io")["PRC2031"]) == (0, 1)
    cold = Interlocking(line.view(20), mode=Mode.CENTER)  # a lab's start: normal, as ever
    assert cold.full_state("io")["PNC2031"] == 1


@pytest.mark.requirement("IXL-INV-02")
def test_a_restarted_interlocking_never_throws_a_point_detected_wrong_under_a_train(
    line: Line,
) -> None:
    """What the whole-system search found (seed 535, docs/system_safety.md): point 32 of station
    18 lay normal under train 2003 in TC1857A, its detection crossed (a wrong-side fault: the
    blades lying normal reported reverse). ixl18 restarted; the new IXL took the position it
    read for its demand, reverse, and the point machine threw the blades under the train, which
    derailed. Restarted, the IXL demands nothing, so the blades stay where they lie, however
    long the train stands there; once it has gone, a control is what moves the point."""
    rig = StationRig(line.view(18), occupied=("TC1857A",))
    rig.from_field(rig.io.fail_point("32", "crossed", rig.now).changes)
    assert rig.ixl.detection("32") == "reverse" and rig.io.blades()["32"] == "normal"
    rig.restart()
    assert rig.ixl.startup_held and rig.ixl.detection("32") == "reverse"
    rig.advance(120.0)  # past station 18's start-up lock (90 s), the train still on the point
    assert not rig.ixl.startup_held
    assert rig.io.blades()["32"] == "normal"
    assert not [e for e in rig.io.log if e.kind == "point"], rig.io.log
    assert rig.control("SRC1832").reason is Reason.TRACK_OCCUPIED
    rig.occupy("TC1857A", False)
    assert rig.control("SRC1832").accepted  # the track clear: the operator's throw is checked
    assert rig.io.blades()["32"] == "moving"


@pytest.mark.requirement("IXL-INV-03")
def test_a_call_is_believed_only_once_the_trackside_has_answered_it(line: Line) -> None:
    """Found by the whole-system search (seed 1244): point 32 of station 18 lay normal, its
    detection crossed (reported reverse). Route 02-22 called it reverse; another control came
    in at the same instant, before the trackside had answered, and the IXL took the reverse it
    had read before its call as proof: the route went set and signal 02 cleared; then the blades
    moved under the set route. A detection counts only once the trackside has reported the
    point since the call (it answers every call)."""
    view = line.view(18)
    ixl = Interlocking(view, mode=Mode.CENTER)
    ixl.link_state("io", True, 0.0)
    ixl.link_state("atc", True, 0.0)
    clear = {t.name: 0 for t in view.track_circuits} | {n.izc(iv.name): 0 for iv in view.intervals}
    ixl.receive("atc", clear, 0.0)
    bits = {f"{b}18{p.name}": 0 for p in view.station.points for b in ("SNI", "SRN", "SRI", "SNR")}
    ixl.receive("io", bits | {"SNI1831": 1, "SRI1832": 1}, 0.0)  # 32 lies normal, crossed
    assert ixl.control("RSC181291", 1, 1.0).results[0].accepted
    assert ixl.detection("32") == "to_reverse"  # called, not yet answered
    ixl.receive("atc", {"TC1851": 0}, 1.0)  # another input before the answer
    assert ixl.route_status("1291") is RouteStatus.SETTING and ixl.aspect("12") == "R"
    ixl.receive("io", {"SNI1832": 0, "SRN1832": 0, "SRI1832": 0, "SNR1832": 1}, 1.02)  # moving
    assert ixl.route_status("1291") is RouteStatus.SETTING
    ixl.receive("io", {"SNR1832": 0, "SNI1832": 1}, 5.0)  # arrived reverse, reported normal
    assert ixl.route_status("1291") is RouteStatus.SETTING and ixl.aspect("12") == "R"
    # restarted (no demand), the point really lying reverse: the answer, its indications
    # unchanged, proves the call
    ixl = Interlocking(view, mode=Mode.CENTER, startup_locking=True)
    ixl.link_state("io", True, 0.0)
    ixl.link_state("atc", True, 0.0)
    ixl.receive("atc", clear, 0.0)
    ixl.receive("io", bits | {"SNI1831": 1, "SRI1832": 1}, 0.0)
    assert ixl.control("RSC181291", 1, 1.0).results[0].accepted
    assert ixl.route_status("1291") is RouteStatus.SETTING
    ixl.receive("io", {"SNI1832": 0, "SRN1832": 0, "SRI1832": 1, "SNR1832": 0}, 1.02)
    assert ixl.route_status("1291") is RouteStatus.SET


def test_the_start_up_lock_timer_waits_while_occupancy_cannot_be_read(line: Line) -> None:
    """Its time past while the ATC link is down, the start-up lock is no deadline (a driver
    would re-run the timer at the same instant without end); the report that brings the link
    back releases it."""
    rig = StationRig(line.view(20), occupied=("TC2047",), startup_locking=True)
    rig.set_link("atc", False)
    rig.advance(120.0)
    deadline = rig.ixl.next_deadline()
    assert rig.ixl.startup_held and (deadline is None or deadline > rig.now)
    rig.set_link("atc", True)
    assert not rig.ixl.startup_held


def test_a_departure_from_the_far_end_cannot_stand_set_while_the_near_end_sends_a_train(
    line: Line,
) -> None:
    """Found by the whole-system search: route 21-92 (down, into interval 1820) stood set at
    station 20 while station 18 sent a train up into 1820 (the two ends did not coordinate the
    interval's direction); station 20's ATC coded its half of 1820 for the down train it meant to
    send, and the up train read that as a proceed past home signal 01 at stop. Now only the
    holder of 1820's permission departs into it: with 21-92 set at 20, 18 is refused."""
    pair = Pair(line)
    assert pair.east.request("RSC202192") is None
    pair.shuttle()
    assert pair.east.results[-1].accepted and pair.holders() == [20]
    assert pair.west.request("RSC181191") is None  # asks 20, which does not give
    pair.advance(4)
    assert pair.west.results[-1].reason is Reason.DIRECTION
    assert pair.west.ixl.route_status("1191") is RouteStatus.IDLE
    assert pair.west.atc[n.tdd("1820")] == 1  # 18's ATC codes 1820 for 20's train
