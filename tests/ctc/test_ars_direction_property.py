"""ARS never sends two trains at each other: a hypothesis state machine over the CTC's tables fed
by hand (`test_ars_direction.Line`), both ends of each interval indicating whatever may happen --
the permission held by either end or by none, asked for or not, circuits of the line occupying and
clearing, routes set and released at any station, time passing, and ARS's requests accepted or
refused at random.

After every step, of what ARS sent in it, against the picture it read:
1. it asked for an interval's permission only at an end not holding it, with the other end
   holding it, every circuit of the interval clear and no departure route into it set at the
   other end;
2. a departure route into an interval between two stations went only from the end holding it;
3. nothing went into one interval from both its ends at once.
KTCS_ARS_EXAMPLES raises the number of runs (default 60 of 50 steps each). Under CI hypothesis
runs derandomized (its `ci` profile) and starts from the first value of each `sampled_from`: the
holders are listed with the far end first so that those runs, too, reach ARS asking.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, rule, run_state_machine_as_test

from ktcs_bench.ctc.ars import DirectionRequest, RouteRequest

from .test_ars_direction import LINE, Line, timetable

INNER = {iv.name: iv for iv in LINE.intervals if not iv.boundary}
TCS = [tc for iv in INNER.values() for tc in iv.track_circuits]  # what a departure would meet
DEPARTS = {  # (station, route) -> the inner interval it departs into
    (st_, r.name): iv.name
    for st_ in LINE.stations
    for r in LINE.station(st_).routes
    if (iv := LINE.view(st_).interval_of_exit(r)) is not None and not iv.boundary
}
ROUTES = sorted(DEPARTS)  # the routes into the intervals, from either end
SEEN = {"asks": 0, "departures": 0}


class Machine(RuleBasedStateMachine):
    @initialize(
        up_to_22=st.sampled_from(["1", "2"]),
        down_to_20=st.sampled_from(["1", "2", "3"]),
        up_depart=st.sampled_from([0, 40, 60]),
        down_depart=st.sampled_from([0, 40, 60]),
        h1820=st.sampled_from([20, 18, None]),
        h2022=st.sampled_from([22, 20, None]),
    )
    def start(self, up_to_22: str, down_to_20: str, up_depart: int, down_depart: int,
              h1820: int | None, h2022: int | None) -> None:  # fmt: skip
        folder = Path(tempfile.mkdtemp(prefix="ars-direction-"))
        tt = timetable(folder, up_to_22, down_to_20, up_depart, down_depart)
        self.line = Line(tt, {"1820": h1820, "2022": h2022})
        self.line.occupied |= {"TC2055", "TC2256"}  # both trains standing, identified
        self.now = 0.0
        self.step()

    def step(self) -> None:
        line = self.line
        line.push()
        picture = {st_: line.state(st_) for st_ in LINE.stations}
        sent = line.ars.update(self.now)
        ends: dict[str, set[int]] = {}
        for r in sent:
            if isinstance(r, DirectionRequest):
                iv = INNER[r.interval]
                other = iv.east if r.station == iv.west else iv.west
                assert line.holders.get(r.interval) == other, (r, line.holders)
                assert not (set(iv.track_circuits) & line.occupied), r
                assert not [x for x in line.routes if x[0] == other
                            and DEPARTS.get(x) == r.interval], r  # fmt: skip
                ends.setdefault(r.interval, set()).add(r.station)
                SEEN["asks"] += 1
            elif isinstance(r, RouteRequest) and (r.station, r.route) in DEPARTS:
                name = DEPARTS[(r.station, r.route)]
                assert picture[r.station][f"PHI{name}"] == 1, (r, line.holders)
                ends.setdefault(name, set()).add(r.station)
                SEEN["departures"] += 1
        assert all(len(s) == 1 for s in ends.values()), ends
        self.sent = sent

    @rule(tc=st.sampled_from(TCS))
    def toggle_circuit(self, tc: str) -> None:
        self.line.occupied ^= {tc}
        self.step()

    @rule(route=st.sampled_from(ROUTES))
    def toggle_route(self, route: tuple[int, str]) -> None:
        self.line.routes ^= {route}
        self.step()

    @rule(iv=st.sampled_from(sorted(INNER)), end=st.sampled_from(["west", "east", "none"]))
    def hand_over(self, iv: str, end: str) -> None:
        i = INNER[iv]
        self.line.holders[iv] = i.west if end == "west" else i.east if end == "east" else None
        self.line.asking = {a for a in self.line.asking if a[1] != iv}
        self.step()

    @rule(seconds=st.sampled_from([0.5, 3.0, 6.0, 31.0]))
    def wait(self, seconds: float) -> None:
        self.now += seconds
        self.step()

    @rule(accept=st.booleans())
    def answer(self, accept: bool) -> None:
        """What ARS sent last comes back accepted (a route then shows set, an ask shows asking)
        or refused."""
        for r in self.sent:
            self.line.ars.result(r, accept, None if accept else "refused", self.now)
            if accept and isinstance(r, RouteRequest):
                self.line.routes.add((r.station, r.route))
            if accept and isinstance(r, DirectionRequest):
                self.line.asking.add((r.station, r.interval))
        self.sent = []
        self.step()


def test_ars_never_sends_two_trains_at_each_other() -> None:
    examples = int(os.environ.get("KTCS_ARS_EXAMPLES", "60"))
    run_state_machine_as_test(
        Machine, settings=settings(max_examples=examples, stateful_step_count=50, deadline=None)
    )
    assert SEEN["asks"] and SEEN["departures"], SEEN  # the runs reached both decisions
