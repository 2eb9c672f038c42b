"""ARS and the intervals' traffic permission (SPEC §6.6), sans-I/O: the CTC's tables are fed
indications as the interlockings would send them, and what ARS asks for is read off its
requests. A departure into an interval its station does not hold waits for the permission it
asks for; it is never asked for against a train in the interval or a route into it from the
other end; of two trains ready to depart into one interval from its two ends one goes first (by
the timetable, or the one standing on the other's arrival track), and the log says why the other
waits."""

from __future__ import annotations

from pathlib import Path

import pytest

from ktcs_bench.ctc.ars import Ars, ArsRequest, DirectionRequest, RouteRequest
from ktcs_bench.ctc.model import CtcModel
from ktcs_bench.station.loader import load_line
from ktcs_bench.station.timetable import Timetable, load_timetable
from ktcs_bench.station_codes import names as n

LINE = load_line()

HEAD = f"""\
timetable: meet
line: {Path(LINE.file).resolve()}
train_data:
  t: {{length_m: 200, max_speed_kmh: 80, traction_kmh_per_s: 3, service_brake_kmh_per_s: 3,
      emergency_brake_kmh_per_s: 4}}
trains:
"""


def timetable(tmp_path: Path, up_to_22: str = "1", down_to_20: str = "2",
              up_depart: float = 40, down_depart: float = 40) -> Timetable:  # fmt: skip
    """1001 up from 20 track 1 to 22; 2001 down from 22 track 2 to 20 and 18."""
    stop22 = {"1": 12680, "2": 12580}[up_to_22]
    stop20 = {"1": 6220, "2": 6120, "3": 6220}[down_to_20]
    text = (
        HEAD
        + f"""\
  - id: "1001"
    train: t
    direction: up
    depart_s: {up_depart}
    stops:
      - {{station: 20, track: "1", stop_m: 6780, dwell_s: 30}}
      - {{station: 22, track: "{up_to_22}", stop_m: {stop22}, dwell_s: 30}}
  - id: "2001"
    train: t
    direction: down
    depart_s: {down_depart}
    stops:
      - {{station: 22, track: "2", stop_m: 12120, dwell_s: 30}}
      - {{station: 20, track: "{down_to_20}", stop_m: {stop20}, dwell_s: 30}}
      - {{station: 18, track: "2", stop_m: 620, dwell_s: 30}}
"""
    )
    path = tmp_path / "meet.yaml"
    path.write_text(text, encoding="utf-8")
    return load_timetable(path, LINE)


class Line:
    """The CTC's tables, fed by hand: every station in center mode, points normal, circuits
    clear, each interval as `permission` says (its holder; the other end shows the holder's
    direction), unless changed."""

    def __init__(self, tt: Timetable, holders: dict[str, int | None]) -> None:
        self.model = CtcModel(LINE)
        self.occupied: set[str] = set()
        self.routes: set[tuple[int, str]] = set()
        self.holders = dict(holders)
        self.asking: set[tuple[int, str]] = set()
        self.worked = True  # False: interlockings from before SPEC §6.6 (no end ever holds)
        self.push()
        self.ars = Ars(self.model, tt, on=(18, 20, 22))

    def state(self, st: int) -> dict[str, int]:
        view = LINE.view(st)
        out = {n.ctc(st): 1}
        for p in view.station.points:
            out[n.sni(st, p.name)] = 1
        for tc in view.track_circuits:
            out[tc.name] = int(tc.name in self.occupied)
        for r in view.station.routes:
            out[n.rsi(st, r.name)] = int((st, r.name) in self.routes)
        for iv in view.intervals:
            holder = self.holders.get(iv.name, iv.west if iv.default_direction == "up"
                                      else iv.east)  # fmt: skip
            d = None if holder is None else "up" if holder == iv.west else "down"
            out[n.tdu(iv.name)] = int(d == "up")
            out[n.tdd(iv.name)] = int(d == "down")
            out[n.phi(iv.name)] = int(holder == st and self.worked)
            out[n.prq(iv.name)] = int((st, iv.name) in self.asking)
        return out

    def push(self) -> None:
        for st in LINE.stations:
            model = self.model.station(st)
            chart = model.indications
            state = dict.fromkeys((c.number for c in chart.codes), 0)
            state.update({chart.number_of(k): v for k, v in self.state(st).items()})
            if not self.model.tables.stations[st].connected:
                self.model.tables.link_up(st, "test")
            self.model.tables.full_state(st, list(state.items()))

    def update(self, now: float) -> list[ArsRequest]:
        self.push()
        return self.ars.update(now)

    def waits(self, train: str) -> str | None:
        return self.ars.progress[train].waiting

    def log(self) -> list[str]:
        return [e["text"] for e in self.ars.log]


def routes(requests: list[ArsRequest]) -> list[tuple[str, int, str]]:
    return [(r.train, r.station, r.route) for r in requests if isinstance(r, RouteRequest)]


def asks(requests: list[ArsRequest]) -> list[tuple[str, int, str]]:
    return [(r.train, r.station, r.interval) for r in requests if isinstance(r, DirectionRequest)]


def standing(line: Line) -> None:
    """Both trains on their first platforms, identified."""
    line.occupied |= {"TC2055", "TC2256"}
    assert line.update(0.0) == []
    assert set(line.ars.describer.trains) == {"1001", "2001"}


def test_a_departure_into_an_interval_held_by_the_other_end_asks_for_it_then_goes(
    tmp_path: Path,
) -> None:
    line = Line(timetable(tmp_path, down_depart=400), {"2022": 22})
    standing(line)
    sent = line.update(45.0)
    assert routes(sent) == [] and asks(sent) == [("1001", 20, "2022")]
    assert line.waits("1001") == "interval 2022 held by 22, asked for it"
    assert "train 1001: asks for the permission of interval 2022 at station 20 (held by 22)" in (
        line.log()
    )
    # the control goes out as DRC2022 at station 20
    action = line.model.action(sent[0].command)
    assert (action.station, action.name, action.value) == (20, "DRC2022", 1)
    line.ars.result(sent[0], True, None, 45.1)
    line.asking.add((20, "2022"))  # 20's IXL asks 22 for it
    assert line.update(45.2) == []  # asked once: not again while the handover runs
    line.holders["2022"] = None  # 22 gives it up first ...
    line.asking.clear()
    assert line.update(45.4) == []
    line.holders["2022"] = 20  # ... and 20 holds it once it has read that
    sent = line.update(45.6)
    assert routes(sent) == [("1001", 20, "1191")] and asks(sent) == []


def test_interlockings_that_work_no_permission_are_left_to_refuse_departures(
    tmp_path: Path,
) -> None:
    """Both ends show 2022's direction alike and neither holds or asks for it (interlockings
    from before SPEC §6.6, whose charts carry PHI at 0): ARS asks for no permission and sets the
    departure as before, with its direction; against it, it waits as before."""
    line = Line(timetable(tmp_path, down_depart=400), {"2022": 20})
    line.worked = False
    standing(line)
    assert line.model.interval("2022").holder is None
    assert routes(line.update(45.0)) == [("1001", 20, "1191")]
    line = Line(timetable(tmp_path, down_depart=400), {"2022": 22})
    line.worked = False
    standing(line)
    line.occupied.add("TC2063")  # 20's half of the interval, the direction down
    assert line.update(45.0) == []
    assert line.waits("1001") == "interval 2022 occupied against the up direction"


def test_the_permission_is_asked_for_again_only_after_a_refusal_waits_out(tmp_path: Path) -> None:
    line = Line(timetable(tmp_path, down_depart=400), {"2022": 22})
    standing(line)
    (ask,) = line.update(45.0)
    line.ars.result(ask, False, "unknown code", 45.1)
    assert line.update(46.0) == []
    assert line.waits("1001") == (
        "interval 2022 held by 22, not given (unknown code), asking again at 50.1 s"
    )
    assert line.ars.next_deadline() == pytest.approx(50.1)
    assert asks(line.update(50.1)) == [("1001", 20, "2022")]


@pytest.mark.parametrize(
    ("occupied", "route", "why"),
    [
        ({"TC2245"}, None, "interval 2022 held by 22, TC2245 occupied"),
        (set(), (22, "2292"), "interval 2022 held by 22, route 22-92 into it set at station 22"),
    ],
)
def test_never_asked_against_a_train_in_the_interval_or_a_route_into_it(
    tmp_path: Path, occupied: set[str], route: tuple[int, str] | None, why: str
) -> None:
    line = Line(timetable(tmp_path, down_depart=400), {"2022": 22})
    standing(line)
    line.occupied |= occupied
    if route is not None:
        line.routes.add(route)
    assert line.update(45.0) == []
    assert line.waits("1001") == why
    assert "1001 waits for route 11-91 at station 20: " + why in " ".join(line.log())


def test_a_train_described_in_the_interval_is_named(tmp_path: Path) -> None:
    line = Line(timetable(tmp_path, down_depart=0), {"2022": 22})
    standing(line)
    (req,) = line.update(31.0)
    assert routes([req]) == [("2001", 22, "2292")]
    line.ars.result(req, True, None, 31.1)
    line.routes.add((22, "2292"))
    # 2001 runs out of 22 into the interval
    line.occupied |= {"TC2253A", "TC2247"}
    line.update(40.0)
    line.occupied -= {"TC2256", "TC2253A"}
    line.routes.clear()
    line.update(41.0)
    assert line.ars.describer.train_at("TC2247").id == "2001"  # type: ignore[union-attr]
    line.update(45.0)
    assert line.waits("1001") == "interval 2022 held by 22, train 2001 in it"


def test_two_trains_ready_for_one_interval_from_its_two_ends_go_in_timetable_order(
    tmp_path: Path,
) -> None:
    """Each end waits for the other only if ARS lets it: here 22 holds 2022, but 1001 at 20
    comes first in the timetable (both due at 40 s): 2001 waits at 22 and says for whom, 20 asks
    for the permission, and 22 does not lock its departure meanwhile."""
    line = Line(timetable(tmp_path), {"2022": 22})
    standing(line)
    sent = line.update(45.0)
    assert asks(sent) == [("1001", 20, "2022")] and routes(sent) == []
    assert line.waits("2001") == "interval 2022 given to train 1001 first (timetable order)"
    assert (
        "train 2001 waits for route 22-92 at station 22: interval 2022 given to train 1001 "
        "first (timetable order)" in line.log()
    )
    # 1001 later due than 2001: 2001 goes at once from the end that holds
    line = Line(timetable(tmp_path / "..", up_depart=50), {"2022": 22})
    standing(line)
    sent = line.update(55.0)
    assert routes(sent) == [("2001", 22, "2292")] and asks(sent) == []
    assert line.waits("1001") == "interval 2022 given to train 2001 first (timetable order)"


def test_the_train_standing_on_the_others_arrival_track_goes_first(tmp_path: Path) -> None:
    """1001 would arrive on 22's track 2, where 2001 stands needing 2022: were 1001 sent first,
    the two would lock each other up. 2001 goes first whatever the timetable order."""
    line = Line(timetable(tmp_path, up_to_22="2"), {"2022": 20})
    standing(line)
    sent = line.update(45.0)
    assert routes(sent) == [] and asks(sent) == [("2001", 22, "2022")]
    assert line.waits("1001") == (
        "interval 2022: train 2001 stands on track 2 at 22 and needs it, it goes first"
    )


def test_each_on_the_others_track_the_timetable_order_decides_and_says_so(tmp_path: Path) -> None:
    line = Line(timetable(tmp_path, up_to_22="2", down_to_20="1", up_depart=60),
                {"2022": 20})  # fmt: skip
    standing(line)
    sent = line.update(65.0)
    # 2001 is first in timetable order (due at 40 s, 1001 at 60 s): 20 keeps its departure back
    assert routes(sent) == [] and asks(sent) == [("2001", 22, "2022")]
    assert line.waits("1001") == (
        "interval 2022: trains 1001 and 2001 each stand on the other's track; 2001 goes first "
        "(timetable order)"
    )


# -- a CTC restarted with trains on the line ---------------------------------------------------

REFERENCE = load_timetable(LINE.file.replace("lines/reference.yaml",
                                             "timetables/reference.yaml"), LINE)  # fmt: skip


def test_a_restarted_ctc_picks_up_the_trains_on_the_line_and_runs_them_on() -> None:
    """The reference timetable's up trains, found at the CTC's start: 1001 standing at 20,
    1003 in interval 1820 behind it. The leading one is the earlier train; 1001 dwells from now
    and leaves at its dwell's end, its first stop's times not waited for again."""
    line = Line(REFERENCE, {})
    line.occupied |= {"TC2055", "TC1863"}
    assert line.update(0.0) == []
    d = line.ars.describer
    assert (d.train_at("TC2055").id, d.train_at("TC1863").id) == ("1001", "1003")  # type: ignore[union-attr]
    # the down train 2001 is not on the line (its entry, TC2261, is clear): still expected
    assert [t.id for t in d.expected] == ["2001"]
    log = line.log()
    assert "train 1001 picked up at TC2055 (on the line as the CTC started)" in log
    assert "train 1001: at station 20 track 1" in log
    assert "train 1003: running to station 20" in log
    assert line.waits("1001") == "dwell until 30.0 s"
    assert routes(line.update(30.0)) == [("1001", 20, "1191")]


def test_a_restarted_ctc_never_sends_a_train_at_one_it_picked_up_in_the_interval(
    tmp_path: Path,
) -> None:
    """2001 is in interval 2022 coming down (22 holds it, the direction shows down) when the CTC
    starts: it is picked up as the down train, and 1001 at 20 waits for it instead of asking for
    the permission."""
    line = Line(timetable(tmp_path, up_depart=0, down_depart=0), {"2022": 22})
    line.occupied |= {"TC2055", "TC2245"}
    line.update(0.0)
    d = line.ars.describer
    assert d.train_at("TC2245").id == "2001"  # type: ignore[union-attr]
    assert d.train_at("TC2055").id == "1001"  # type: ignore[union-attr]
    assert "train 2001: running to station 20" in line.log()
    assert line.update(31.0) == []
    assert line.waits("1001") == "interval 2022 held by 22, train 2001 in it"


def test_no_train_is_picked_up_from_a_picture_not_yet_whole() -> None:
    """A station not yet known (or showing its fail-safe picture) holds the pick-up back: a run
    of circuits is not named from half the line."""
    line = Line(REFERENCE, {})
    line.occupied |= {"TC2055"}
    line.push()
    line.model.tables.link_down(22)
    assert line.ars.update(0.0) == []
    assert line.ars.describer.trains == {}
    line.model.tables.link_up(22, "test")
    assert line.update(1.0) == []
    assert set(line.ars.describer.trains) == {"1001"}


def test_a_rival_that_cannot_have_the_permission_does_not_hold_the_holder_back(
    tmp_path: Path,
) -> None:
    """1001 at 20 is first in timetable order, but its ask is refused (the link between 20 and
    22 down, say): meanwhile 2001 leaves from 22, which holds the interval."""
    line = Line(timetable(tmp_path), {"2022": 22})
    standing(line)
    (ask,) = line.update(45.0)
    assert asks([ask]) == [("1001", 20, "2022")]
    line.ars.result(ask, False, "direction", 45.5)
    assert routes(line.update(46.0)) == [("2001", 22, "2292")]
    assert line.waits("1001") == (
        "interval 2022 held by 22, not given (direction), asking again at 50.5 s"
    )


def test_the_describer_picks_up_by_the_direction_shown_and_leaves_what_no_path_covers(
    tmp_path: Path,
) -> None:
    """The same run of circuits in interval 2022 is the down train where the interval shows down
    and the up train where it shows up; a train in the siding no timetable train runs over is
    left unexplained."""
    from ktcs_bench.ctc.describer import Describer

    tt = timetable(tmp_path)
    occupancy = {tc.name: False for tc in LINE.all_track_circuits()}
    occupancy.update({"TC2245": True, "TC2254": True})
    for shown, train in (("down", "2001"), ("up", "1001")):
        d = Describer(LINE, tt)
        hints = dict.fromkeys(LINE.intervals[2].track_circuits, shown)
        events = d.pick_up(occupancy, 5.0, hints)  # type: ignore[arg-type]
        assert [(e.train, e.kind, e.track_circuit) for e in events] == [
            (train, "picked up", "TC2245")
        ]
        assert d.trains[train].picked_up and d.trains[train].identified_at == 5.0
        assert [e.kind for e in d.update(occupancy, 5.0)] == ["unexplained"]  # the siding


# -- a whole meet, the interlockings' permission rules played by the test -----------------------

MEET = """\
  - id: "1001"
    train: t
    direction: up
    stops:
      - {station: 18, track: "1", stop_m: 1080, dwell_s: 30}
      - {station: 20, track: "1", stop_m: 6780, dwell_s: 30}
      - {station: 22, track: "1", stop_m: 12680, dwell_s: 30}
  - id: "2001"
    train: t
    direction: down
    stops:
      - {station: 22, track: "2", stop_m: 12120, dwell_s: 30}
      - {station: 20, track: "2", stop_m: 6120, dwell_s: 30}
      - {station: 18, track: "2", stop_m: 620, dwell_s: 30}
"""


def test_an_up_and_a_down_train_cross_at_20_without_meeting_between_stations(
    tmp_path: Path,
) -> None:
    """1001 up 18 -> 20 -> 22 and 2001 down 22 -> 20 -> 18, both leaving at once. The test plays
    the interlockings as SPEC §6.6 has them (a departure only from the holder; the permission
    given only with the interval clear and no departure route of the holder's into it) and
    moves each train one circuit at a time where a route of its direction is set. ARS asks for
    each permission it needs; the two cross at station 20, never in one interval together, and
    both reach their last stop."""
    path = tmp_path / "meet.yaml"
    path.write_text(HEAD + MEET, encoding="utf-8")
    tt = load_timetable(path, LINE)
    line = Line(tt, {})  # 1820 held by 18, 2022 by 20: the line's default (up)
    paths = {t.id: _path(t.id, tt) for t in tt.trains}
    at = {t: p[0] for t, p in paths.items()}
    line.occupied = set(at.values())
    directions = {t.id: t.direction for t in tt.trains}
    inner = {iv.name: iv for iv in LINE.intervals if not iv.boundary}
    departs = {(s, r.name): iv.name for s in LINE.stations for r in LINE.station(s).routes
               if (iv := LINE.view(s).interval_of_exit(r)) is not None and not iv.boundary}  # fmt: skip

    def answer(r: ArsRequest) -> tuple[bool, str | None]:
        if isinstance(r, DirectionRequest):
            iv = inner[r.interval]
            holder = line.holders.get(r.interval, iv.west)
            clear = not set(iv.track_circuits) & line.occupied
            locked = any(departs.get(x) == r.interval and x[0] == holder for x in line.routes)
            if clear and not locked:
                line.holders[r.interval] = r.station
            return True, None
        route = LINE.station(r.station).route(r.route)
        into = departs.get((r.station, r.route))
        if into is not None and line.holders.get(into, inner[into].west) != r.station:
            return False, "direction"
        if any((r.station, c) in line.routes for c in route.conflicts):
            return False, "route conflicts"
        if set(route.all_track_circuits) & line.occupied:
            return False, "track occupied"
        line.routes.add((r.station, r.route))
        return True, None

    def move(train: str) -> None:
        p, i = paths[train], paths[train].index(at[train])
        if i + 1 == len(p) or p[i + 1] in line.occupied:
            return
        nxt, in_iv = p[i + 1], any(p[i + 1] in iv.track_circuits for iv in inner.values())
        was_in_iv = any(at[train] in iv.track_circuits for iv in inner.values())
        routed = [x for x in line.routes if nxt in LINE.station(x[0]).route(x[1]).track_circuits
                  and LINE.station(x[0]).route(x[1]).direction == directions[train]]  # fmt: skip
        platform = at[train] in {c.name for c in LINE.all_track_circuits() if len(c.tracks) == 1}
        if not routed and not (in_iv and (was_in_iv or not platform)):
            return  # (out of a station's last points into the interval: its route ran there)
        line.occupied.discard(at[train])
        at[train] = nxt
        line.occupied.add(nxt)
        for x in list(line.routes):  # a route the train has run into releases behind it
            tcs = LINE.station(x[0]).route(x[1]).track_circuits
            if p[i] in tcs and (nxt not in tcs or nxt == tcs[-1]):
                line.routes.discard(x)

    for second in range(1500):
        now = float(second)
        for r in line.update(now):
            ok, why = answer(r)
            line.ars.result(r, ok, why, now)
        if second % 3 == 0:
            for train in sorted(at):
                move(train)
        for iv in inner.values():  # never two trains in one interval
            assert len([t for t, tc in at.items() if tc in iv.track_circuits]) <= 1, (now, at)
    assert at == {t: p[-1] for t, p in paths.items()}, "\n".join(line.log())
    states = {t["train"]: t["state"] for t in line.ars.status()["trains"]}
    assert states == {"1001": "terminated at station 22 track 1",
                      "2001": "terminated at station 18 track 2"}  # fmt: skip
    log = " ".join(line.log())
    assert "train 2001: asks for the permission of interval 2022 at station 22" in log
    assert "train 2001: asks for the permission of interval 1820 at station 20" in log


def _path(train: str, tt: Timetable) -> list[str]:
    """The circuits `train` runs over, in order: each platform, the route out, the interval,
    the route into the next platform."""
    t = tt.train(train)
    up = t.direction == "up"
    out: list[str] = []

    def add(tcs: list[str]) -> None:
        key = {c.name: c.from_m for c in LINE.all_track_circuits()}
        for tc in sorted(tcs, key=lambda c: key[c], reverse=not up):
            if not out or out[-1] != tc:
                out.append(tc)

    for k, stop in enumerate(t.stops):
        st_ = LINE.station(stop.station)
        if stop.home_route is not None:
            add(list(st_.route(stop.home_route).track_circuits))
        else:
            add([c.name for c in st_.track_circuits if c.tracks == (stop.track,)])
        if stop.start_route is not None and k + 1 < len(t.stops):
            route = st_.route(stop.start_route)
            add(list(route.track_circuits))
            iv = LINE.view(stop.station).interval_of_exit(route)
            assert iv is not None
            add(list(iv.track_circuits))
    return out
