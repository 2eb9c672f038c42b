"""The binding between a core and its links: names on the core's side, numbers on the wire, one
difference per hop (the core's), a full state read from the core's own table, and what a link
that was down is owed."""

from __future__ import annotations

import pytest

from ktcs_bench.binding import ControlLink, LinkBinding
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes.stations import link_charts


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


def test_a_route_set_crosses_each_hop_as_the_core_s_changes_once(line: Line) -> None:
    """The IXL's own changes go out item for item: the binding neither drops nor adds one, and
    the peer's binding reads back exactly the names the IXL gave."""
    rig = StationRig(line.view(18))
    ixl = rig.ixl
    to_atc = LinkBinding(*link_charts(rig.view, "ixl_to_atc"), lambda: ixl.full_state("atc"),
                         up=True)  # fmt: skip
    to_io = LinkBinding(*link_charts(rig.view, "ixl_to_io"), lambda: ixl.full_state("io"), up=True)
    atc_end = LinkBinding(*link_charts(rig.view, "atc_to_ixl"), dict)
    io_end = LinkBinding(*link_charts(rig.view, "io_to_ixl"), dict)
    out = ixl.control("RSC180112", 1, rig.now)
    assert out.of("io") and out.of("atc")  # point 31 demanded reverse; the route locked for the ATC
    for binding, peer, changes in ((to_atc, atc_end, out.of("atc")), (to_io, io_end, out.of("io"))):
        items = binding.send(changes)
        assert len(items) == len(changes)
        names, unknown = peer.received(items)
        assert names == dict(changes) and unknown == []


def test_the_binding_does_not_difference_again() -> None:
    """A change the core gives is carried even if the same value went before: the core's diff is
    the only one (the code port used to drop what it thought already sent)."""
    view = load_line().view(20)
    tx, rx = link_charts(view, "atc_to_ixl")
    tc = tx.codes[0].name
    state = {tc: 1}
    binding = LinkBinding(tx, rx, lambda: state, up=True)
    assert binding.send([(tc, 1)]) == [(1, 1)]
    assert binding.send([(tc, 1)]) == [(1, 1)]
    assert binding.send([("SNI2031", 1)]) == []  # not a code of this link: not carried


def test_a_full_state_is_the_core_s_table_in_chart_order() -> None:
    view = load_line().view(20)
    tx, rx = link_charts(view, "atc_to_ixl")
    state = {c.name: 0 for c in tx.codes}
    binding = LinkBinding(tx, rx, lambda: state)
    state[tx.codes[2].name] = 1  # the core moved on; nothing was sent yet
    assert binding.full_state() == [(c.number, int(c.number == 3)) for c in tx.codes]
    assert binding.statuses() == [int(c.number == 3) for c in tx.codes]


def test_a_link_that_was_down_is_owed_what_changed_then_everything() -> None:
    view = load_line().view(18)
    tx, rx = link_charts(view, "io_to_ixl")
    state = {c.name: 0 for c in tx.codes}
    binding = LinkBinding(tx, rx, lambda: state)  # down until the link comes up
    a, b = tx.codes[0].name, tx.codes[4].name
    state[a] = 1
    assert binding.send([(a, 1)]) == []  # down: owed
    state[a] = 0  # changed again before the link came up: the current state is owed
    assert binding.link_up() == [(1, 0)]
    assert binding.link_up() == []  # paid
    state[b] = 1
    assert binding.send([(b, 1)]) == [(5, 1)]
    binding.link_down()  # what was queued is lost: everything is owed
    assert binding.send([(a, 1)]) == []
    state[a] = 1
    assert sorted(binding.link_up()) == sorted(binding.full_state())


def test_numbers_in_are_names_and_unknown_numbers_are_told() -> None:
    view = load_line().view(18)
    binding = LinkBinding(*link_charts(view, "ixl_to_atc"), dict)
    rx = binding.rx
    names, unknown = binding.received([(1, 1), (len(rx) + 1, 1), (0, 1)])
    assert names == {rx.codes[0].name: 1} and unknown == [len(rx) + 1, 0]
    statuses = [1] + [0] * (len(rx) - 2)  # one short: the last code is left out
    full = binding.received_all(statuses)
    assert full[rx.codes[0].name] == 1 and len(full) == len(rx) - 1


def test_controls_by_number_reach_the_core_by_name(line: Line) -> None:
    view = line.view(20)
    given: list[tuple[str, int]] = []
    told: list[tuple[int, int]] = []

    def control(name: str, value: int) -> tuple[bool, int]:
        given.append((name, value))
        return True, 0

    link = ControlLink(
        *link_charts(view, "ixl_to_ctc"), dict, control, int(Reason.UNKNOWN_CODE),
        lambda code, value: told.append((code, value)),
    )  # fmt: skip
    assert link.on_control(link.rx.number_of("SSC2001"), 0) == (True, 0)
    assert given == [("SSC2001", 0)]
    assert link.on_control(60000, 1) == (False, int(Reason.UNKNOWN_CODE))
    assert given == [("SSC2001", 0)] and told == [(60000, 1)]
    assert link.up  # a Type II link owes nothing: every connection starts with a full state
