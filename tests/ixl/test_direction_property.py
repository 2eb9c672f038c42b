"""The interval permission under random commands and faults (SPEC §6.6, §6.2 invariant 5).

Two interlockings, 18 and 20, linked across interval 1820 (`direction_pair.Pair`); hypothesis
drives departures asked at both ends, DRC asks, cancels, trains in the interval and on the
departures' approaches, messages lost or held back, the link failing and coming back, and
restarts. After every step: never both ends holding the permission, never departure routes into
1820 locked at both ends, and a departure locked only at the holder.
"""

from __future__ import annotations

import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule, run_state_machine_as_test

from ktcs_bench.ixl import RouteStatus
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station import load_line
from ktcs_bench.station_codes import names as n

from .direction_pair import INTERVAL, Pair

LINE = load_line()
DEPARTURES = {18: ("1191", "1291"), 20: ("2192", "2292", "2392")}
# the interval's track circuits and each departure's approach, by the station that owns them
TRACK = {
    18: ("TC1861A", "TC1863", "TC1867", "TC1855", "TC1856", "TC1857A"),
    20: ("TC2043", "TC2045", "TC2047", "TC2055", "TC2056", "TC2054", "TC2053A", "TC2053B"),
}
SEEN = {"handovers": 0, "refused": 0, "steps": 0}


class PermissionMachine(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.pair = Pair(LINE)
        self.hold = False  # messages held back (delivered late, in order)
        self.last_holder = 18  # the default end, after the first resync

    def rig(self, station: int) -> StationRig:
        return self.pair.west if station == 18 else self.pair.east

    def carry(self) -> None:
        if not self.hold:
            self.pair.shuttle()

    @rule(station=st.sampled_from([18, 20]), k=st.integers(0, 2))
    def depart(self, station: int, k: int) -> None:
        routes = DEPARTURES[station]
        name = n.rsc(station, routes[k % len(routes)])
        if self.pair.is_up or station == 18:
            result = self.rig(station).request(name)
            if result is not None and not result.accepted:
                SEEN["refused"] += 1
        self.carry()

    @rule(station=st.sampled_from([18, 20]), k=st.integers(0, 2))
    def cancel(self, station: int, k: int) -> None:
        routes = DEPARTURES[station]
        self.rig(station).request(n.rcc(station, routes[k % len(routes)]))
        self.carry()

    @rule(station=st.sampled_from([18, 20]))
    def ask(self, station: int) -> None:
        self.rig(station).request(n.drc(INTERVAL))
        self.carry()

    @rule(station=st.sampled_from([18, 20]), k=st.integers(0, 7), occupied=st.booleans())
    def train(self, station: int, k: int, occupied: bool) -> None:
        tcs = TRACK[station]
        self.rig(station).occupy(tcs[k % len(tcs)], occupied)
        self.carry()

    @rule(seconds=st.sampled_from([0.5, 1.0, 2.0, 3.5, 10.0]))
    def wait(self, seconds: float) -> None:
        if self.hold:
            for rig in (self.pair.west, self.pair.east):
                rig.advance(seconds)
        else:
            self.pair.advance(seconds)

    @rule(drop=st.booleans())
    def lose(self, drop: bool) -> None:
        """Messages lost from now (or no longer); a lost message is soon a link failure."""
        self.pair.drop = drop

    @rule(hold=st.booleans())
    def delay(self, hold: bool) -> None:
        self.hold = hold
        self.carry()

    @rule(up=st.booleans())
    def link(self, up: bool) -> None:
        self.pair.link(up)

    @rule(station=st.sampled_from([18, 20]))
    def restart(self, station: int) -> None:
        self.pair.restart(station)

    @invariant()
    def at_most_one_holder(self) -> None:
        SEEN["steps"] += 1
        holders = self.pair.holders()
        assert len(holders) <= 1, holders
        if holders and holders[0] != self.last_holder:
            SEEN["handovers"] += 1
            self.last_holder = holders[0]

    @invariant()
    def departures_into_the_interval_only_from_the_holder(self) -> None:
        locked = []
        for station, routes in DEPARTURES.items():
            ixl = self.rig(station).ixl
            if any(ixl.route_status(r) is not RouteStatus.IDLE for r in routes):
                locked.append(station)
                assert ixl.ends[INTERVAL].holds, f"station {station}: departure without permission"
        assert len(locked) <= 1, locked  # SPEC §6.2 invariant 5


@pytest.mark.requirement("DIR-01", "DIR-05", "IXL-INV-05")
def test_the_permission_is_never_held_at_both_ends_nor_departures_locked_from_both() -> None:
    run_state_machine_as_test(
        PermissionMachine,
        settings=settings(max_examples=150, stateful_step_count=40, deadline=None),
    )
    assert SEEN["steps"] >= 2000, SEEN
    assert SEEN["refused"] > 0 and SEEN["handovers"] > 0, (
        SEEN
    )  # both ways, not only checked on nothing
