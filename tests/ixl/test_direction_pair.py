"""Two interlockings, 18 and 20, working interval 1820 between them (SPEC §6.6): the permission."""

from __future__ import annotations

import pytest

from ktcs_bench.ixl import Reason, RouteStatus
from ktcs_bench.ixl.direction import ASK_TIMEOUT_S, Holding
from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes import names as n

from .direction_pair import INTERVAL, Pair


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


@pytest.fixture()
def pair(line: Line) -> Pair:
    return Pair(line)


def test_the_default_end_holds_once_the_link_has_resynced(line: Line) -> None:
    pair = Pair(line, up=False)
    assert pair.holders() == []  # nothing known before the link
    assert pair.west.ixl.holding(INTERVAL) is Holding.UNKNOWN
    assert pair.west.ctc[n.tdu(INTERVAL)] == 0 and pair.west.ctc[n.tdd(INTERVAL)] == 0
    pair.link(True)
    assert pair.holders() == [18]  # default up: station 18's departures
    for rig in (pair.west, pair.east):
        assert rig.ctc[n.tdu(INTERVAL)] == 1 and rig.atc[n.tdu(INTERVAL)] == 1
    assert pair.west.ctc[n.phi(INTERVAL)] == 1 and pair.east.ctc[n.phi(INTERVAL)] == 0


def test_the_opposing_departure_is_refused_while_the_holder_s_departure_is_locked(
    pair: Pair,
) -> None:
    assert pair.west.control("RSC181191").accepted  # up into 1820: 18 holds
    pair.shuttle()
    assert pair.east.request("RSC202192") is None  # down into 1820: asks 18, waits
    pair.shuttle()
    assert pair.east.ctc[n.prq(INTERVAL)] == 1
    assert pair.holders() == [18]  # 18 does not give: its departure is locked
    pair.advance(ASK_TIMEOUT_S + 0.5)
    (result,) = pair.east.results
    assert result.name == "RSC202192" and result.reason is Reason.DIRECTION
    assert pair.east.ixl.route_status("2192") is RouteStatus.IDLE
    assert pair.west.ixl.route_status("1191") is not RouteStatus.IDLE
    assert pair.holders() == [18] and pair.east.ctc[n.prq(INTERVAL)] == 0


def test_a_handover_on_a_clear_interval_sets_the_waiting_route(pair: Pair) -> None:
    assert pair.east.request("RSC202192") is None
    pair.shuttle()
    (result,) = pair.east.results
    assert result.accepted and result.name == "RSC202192"
    assert pair.holders() == [20]
    assert pair.east.ixl.route_status("2192") is not RouteStatus.IDLE
    for rig in (pair.west, pair.east):  # both ends code 1820 down now
        assert rig.atc[n.tdd(INTERVAL)] == 1 and rig.atc[n.tdu(INTERVAL)] == 0
    pair.advance(5)
    assert pair.east.ixl.aspect("21") != "R"
    # and back: 18's departure now waits, and is refused while 20's route is locked
    assert pair.west.request("RSC181191") is None
    pair.advance(ASK_TIMEOUT_S + 0.5)
    assert [r.reason for r in pair.west.results] == [Reason.DIRECTION]
    assert pair.holders() == [20]


def test_the_holder_does_not_give_while_the_far_half_is_occupied(pair: Pair) -> None:
    pair.east.occupy("TC2045")  # a train in 20's half of 1820
    pair.shuttle()
    assert pair.east.request("RSC202192") is None
    pair.shuttle()
    assert pair.holders() == [18]
    pair.advance(ASK_TIMEOUT_S + 0.5)
    assert [r.reason for r in pair.east.results] == [Reason.DIRECTION]


def test_a_departure_into_the_interval_sends_a_train_the_holder_follows_until_it_arrived(
    pair: Pair,
) -> None:
    """The holder gives nothing while a train it sent is in the interval, nor once the train has
    gone from its half without being seen in the far half (a train in transit)."""
    assert pair.west.control("RSC181191").accepted
    pair.advance(5)
    assert pair.west.ixl.aspect("11") != "R"
    pair.west.occupy("TC1855")  # the train at signal 11
    pair.west.occupy("TC1857A")  # past it: the route is entered
    pair.west.occupy("TC1861A")  # into the interval
    pair.west.occupy("TC1855", False)
    pair.west.occupy("TC1857A", False)
    pair.advance(1)
    pair.west.occupy("TC1861A", False)  # gone from our half, never seen in 20's: in transit
    pair.advance(1)
    assert pair.west.ixl.route_status("1191") is RouteStatus.IDLE
    assert pair.east.request("RSC202192") is None
    pair.advance(ASK_TIMEOUT_S + 0.5)
    assert [r.reason for r in pair.east.results] == [Reason.DIRECTION]
    pair.east.occupy("TC2043")  # it is seen in the far half, then arrives
    pair.shuttle()
    pair.east.occupy("TC2043", False)
    pair.shuttle()
    assert pair.east.request("RSC202192") is None
    pair.shuttle()
    assert pair.east.results[-1].accepted and pair.holders() == [20]


def test_with_the_link_down_the_holder_departs_and_the_other_end_refuses_at_once(
    pair: Pair,
) -> None:
    pair.link(False)
    assert pair.west.control("RSC181191").accepted  # the holder keeps holding
    pair.advance(5)
    assert pair.west.ixl.aspect("11") != "R"  # the neighbour link is no signal's condition
    assert pair.east.control("RSC202192").reason is Reason.DIRECTION  # cannot ask: refused now
    assert pair.east.atc[n.tdu(INTERVAL)] == 1  # it knows the neighbour held it
    pair.link(True)
    assert pair.holders() == [18]


def test_a_lost_message_leaves_neither_holding_until_the_link_resyncs(pair: Pair) -> None:
    assert pair.east.request("RSC202192") is None
    pair.drop = True  # the ask is lost: nothing comes
    pair.shuttle()
    pair.advance(ASK_TIMEOUT_S + 0.5)
    assert [r.reason for r in pair.east.results] == [Reason.DIRECTION]
    assert pair.holders() == [18]
    # 18 gives, the gift is lost: nobody holds it until the link's resync says who does
    pair.drop = False
    pair.east.results.clear()
    assert pair.east.request("RSC202192") is None
    pair.drop = True
    east_says = dict(pair.east.to_neighbour["west"])
    pair.drop = False
    pair.west.deliver("east", east_says)  # 18 reads the ask ...
    pair.east.to_neighbour["west"].clear()
    pair.drop = True  # ... and its gift is lost
    pair.shuttle()
    assert pair.holders() == []
    assert pair.west.control("RSC181191").reason is Reason.DIRECTION  # neither departs
    pair.advance(ASK_TIMEOUT_S + 0.5)
    assert pair.holders() == [] and pair.east.results[-1].reason is Reason.DIRECTION
    pair.drop = False
    pair.link(False)  # the loss is a communication error ...
    pair.link(True)  # ... and the resync finds nobody: the default end takes it, clear
    assert pair.holders() == [18]


def test_a_restarted_interlocking_knows_no_permission_until_the_link_resynced(
    pair: Pair,
) -> None:
    assert pair.east.request("RSC202192") is None
    pair.shuttle()
    assert pair.holders() == [20]
    pair.restart(20)  # the holder restarts: it forgets
    assert pair.east.ixl.holding(INTERVAL) is Holding.UNKNOWN
    assert pair.east.control("RSC202292").reason in (Reason.DIRECTION, Reason.ROUTE_CONFLICTS)
    assert pair.holders() == []
    pair.link(True)  # nobody holds it: the default end takes it, the interval being clear
    assert pair.holders() == [18]
    assert pair.east.ixl.holding(INTERVAL) is Holding.NOT_HOLDER


def test_after_a_restart_with_the_interval_occupied_nobody_holds_until_it_clears(
    pair: Pair,
) -> None:
    pair.east.occupy("TC2045")
    pair.shuttle()
    pair.restart(18)
    pair.link(True)
    assert pair.holders() == []  # 18 forgot, and may not take it while 1820 is occupied
    assert pair.west.control("RSC181191").reason is Reason.DIRECTION
    pair.east.occupy("TC2045", False)
    pair.shuttle()
    pair.west.advance(0.1)
    assert pair.holders() == [18]


def test_drc_asks_for_the_permission_ahead_of_a_route(pair: Pair) -> None:
    assert pair.east.control(n.drc(INTERVAL)).accepted
    pair.shuttle()
    assert pair.holders() == [20]
    assert pair.east.control("RSC202192").accepted  # at once now
    pair.link(False)
    assert pair.west.control(n.drc(INTERVAL)).reason is Reason.DIRECTION  # cannot ask
