"""One end of an interval's permission (`ixl.direction.IntervalEnd`), fed by hand (SPEC §6.6)."""

from __future__ import annotations

import pytest

from ktcs_bench.ixl.direction import ASK_TIMEOUT_S, Facts, Holding, IntervalEnd
from ktcs_bench.station import load_line
from ktcs_bench.station.model import Interval
from ktcs_bench.station_codes.names import Function as F

LINE = load_line()
IV = next(iv for iv in LINE.intervals if iv.name == "1820")  # default up: 18 is the default end
EDGE = next(iv for iv in LINE.intervals if iv.name == "2224")  # boundary, default down
CLEAR = Facts(clear=True, departure_locked=False, in_transit=False)
OCCUPIED = Facts(clear=False, departure_locked=False, in_transit=False)


def synced(station: int, phi: int, interval: Interval = IV) -> IntervalEnd:
    end = IntervalEnd(interval, station, linked=True)
    end.link_state(True, 0.0)
    for f, v in ((F.PHI, phi), (F.PRQ, 0), (F.DRL, 0), (F.TTC, 0)):
        end.receive(f, v, 0.0)
    return end


def test_a_linked_end_knows_nothing_until_its_link_resynced() -> None:
    end = IntervalEnd(IV, 18, linked=True)
    assert end.holding is Holding.UNKNOWN and end.direction is None and not end.ask(0.0)
    end.link_state(True, 0.0)
    end.receive(F.PHI, 0, 0.0)
    assert not end.synced  # part of the neighbour's picture is not a resync
    assert end.step(CLEAR, 0.0) == [] and end.holding is Holding.UNKNOWN


def test_after_a_resync_the_one_that_says_it_holds_holds() -> None:
    end = synced(20, phi=1)
    assert end.holding is Holding.NOT_HOLDER and end.direction == "up"  # 18's trains come
    end = synced(18, phi=1)
    assert not end.holds  # even the default end does not take what the other holds


@pytest.mark.requirement("DIR-02")
def test_with_nobody_holding_the_default_end_takes_it_once_the_interval_is_clear() -> None:
    default, other = synced(18, phi=0), synced(20, phi=0)
    default.step(OCCUPIED, 0.0)
    other.step(CLEAR, 0.0)
    assert not default.holds and not other.holds
    assert not other.ask(0.0)  # nobody to ask: refused at once
    assert "the default end takes it" in " ".join(default.step(CLEAR, 1.0))
    assert default.holds and default.phi == 1 and default.direction == "up"


@pytest.mark.requirement("DIR-04", "DIR-05")
def test_the_holder_gives_only_when_asked_and_free_and_stops_holding_first() -> None:
    holder = synced(18, phi=0)
    holder.step(CLEAR, 0.0)
    assert holder.holds
    holder.receive(F.PRQ, 1, 0.0)
    for busy in (
        OCCUPIED,
        Facts(clear=True, departure_locked=True, in_transit=False),
        Facts(clear=True, departure_locked=False, in_transit=True),
    ):
        holder.step(busy, 0.0)
        assert holder.holds
    assert holder.step(CLEAR, 0.0) == ["permission given to the neighbour"]
    assert not holder.holds and holder.phi == 0 and holder.direction is None


def test_the_asker_takes_it_when_it_reads_the_gift_and_not_before() -> None:
    asker = synced(20, phi=1)
    assert asker.ask(5.0) and asker.holding is Holding.ASKING and asker.prq == 1
    assert asker.next_deadline() == 5.0 + ASK_TIMEOUT_S
    asker.step(CLEAR, 6.0)
    assert asker.holding is Holding.ASKING
    asker.receive(F.PHI, 0, 6.5)  # the holder's PHI goes 1 -> 0: given
    assert not asker.holds  # read with the rest of its message, at the evaluation
    asker.step(CLEAR, 6.5)
    assert asker.holds and asker.prq == 0 and asker.direction == "down"
    assert asker.next_deadline() is None


@pytest.mark.requirement("DIR-03")
def test_an_ask_without_answer_fails_after_its_time() -> None:
    asker = synced(20, phi=1)
    asker.ask(0.0)
    asker.step(CLEAR, ASK_TIMEOUT_S - 0.1)
    assert asker.holding is Holding.ASKING
    assert asker.step(CLEAR, ASK_TIMEOUT_S) == [
        f"ask failed: no permission within {ASK_TIMEOUT_S:g} s"
    ]
    assert asker.holding is Holding.NOT_HOLDER and asker.prq == 0
    asker.receive(F.PHI, 0, 4.0)  # the gift was on its way: still a gift
    asker.step(CLEAR, 4.0)
    assert asker.holds


@pytest.mark.requirement("DIR-06")
def test_a_link_failure_changes_nothing_hands_and_a_resync_is_never_read_as_a_gift() -> None:
    holder, asker = synced(18, phi=0), synced(20, phi=1)
    holder.step(CLEAR, 0.0)
    asker.ask(0.0)
    holder.link_state(False, 1.0)
    asker.link_state(False, 1.0)
    assert holder.holds  # keeps it: departs with its link down
    assert asker.holding is Holding.NOT_HOLDER and not asker.ask(1.0)
    assert asker.direction == "up"  # the neighbour held it when last heard
    asker.link_state(True, 2.0)
    for f, v in ((F.PHI, 0), (F.PRQ, 0), (F.DRL, 0), (F.TTC, 0)):  # a restarted neighbour
        asker.receive(f, v, 2.0)
    assert not asker.holds and asker.direction is None  # PHI 0 on a resync: nobody holds it


def test_without_a_neighbour_link_the_default_end_holds_it_for_good() -> None:
    near, far = IntervalEnd(IV, 18, linked=False), IntervalEnd(IV, 20, linked=False)
    assert near.holds and not far.holds and not far.ask(0.0)
    near.step(OCCUPIED, 0.0)
    assert near.holds and near.direction == far.direction == "up"


def test_a_boundary_interval_runs_our_way_only_while_our_departure_runs_out() -> None:
    edge = IntervalEnd(EDGE, 22, linked=True)  # no IXL beyond: never linked
    assert not edge.linked and edge.direction == "down"  # trains come in from the lab's edge
    assert not edge.take_boundary(OCCUPIED)
    assert edge.take_boundary(CLEAR) and edge.direction == "up"
    edge.step(Facts(clear=True, departure_locked=True, in_transit=False), 0.0)
    edge.step(Facts(clear=False, departure_locked=False, in_transit=False), 1.0)
    assert edge.direction == "up"  # the train is still in it
    edge.step(CLEAR, 2.0)
    assert edge.direction == "down"


def test_a_neighbour_that_lets_go_unasked_forgot_it() -> None:
    """A holder restarted and back before this end saw its link fail says PHI 0: no gift (the
    search's head-on in 2022). Nobody holds it until the interval is clear; then the default
    end takes it."""
    end = synced(18, phi=1)  # 20 holds 1820 against the default
    end.step(CLEAR, 0.0)
    end.receive(F.PHI, 0, 1.0)  # unasked
    end.receive(F.TTC, 1, 1.0)  # in the same message: its half occupied
    assert "without giving it" in " ".join(end.step(OCCUPIED, 1.0))
    assert not end.holds and end.direction is None  # a train may be in it: nobody departs
    end.step(CLEAR, 2.0)
    assert end.holds


def test_a_gift_is_read_with_the_rest_of_its_message() -> None:
    """The giver's PHI 0 and its DRL 0 come in one message, PHI first: still a gift."""
    end = synced(20, phi=1)
    end.receive(F.DRL, 1, 0.2)
    assert end.ask(0.5)
    end.receive(F.PHI, 0, 1.0)
    end.receive(F.DRL, 0, 1.0)
    end.step(CLEAR, 1.0)
    assert end.holds


def test_a_gift_while_asking_needs_what_a_giver_says() -> None:
    """Asking when the holder restarts: its PHI 0 comes with its departure still locked (as last
    heard), so it is no gift."""
    end = synced(20, phi=1)  # not the default end of 1820: it does not take what nobody holds
    end.receive(F.DRL, 1, 0.5)  # 18 locked a departure into 1820
    assert end.ask(1.0) and end.holding is Holding.ASKING
    end.receive(F.PHI, 0, 1.5)
    end.step(CLEAR, 1.5)
    assert not end.holds and end.holding is Holding.NOT_HOLDER
