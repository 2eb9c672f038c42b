"""Trains run where the point blades lie (SPEC §6.7): the track-circuit model, sans-I/O.

Station 18: point 31 at 550 m (its toe faces up trains: plain line below, track 1 normal, track 2
reverse), point 32 at 1150 m (its toe faces down trains); TC1853A 500-600 (31), TC1855 track 1 and
TC1856 track 2 600-1100, TC1857A 1100-1200 (32).
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.atc import TrackCircuitModel, TrainPosition
from ktcs_bench.atc.track_circuits import RailEvent
from ktcs_bench.station import Line, load_line

LINE = load_line()


@pytest.fixture(scope="module")
def line() -> Line:
    return LINE


def occupied(model: TrackCircuitModel) -> set[str]:
    return {k for k, v in model.occupancy().items() if v}


def run(model: TrackCircuitModel, train: str, start: float, end: float, length: float = 40.0,
        track: str = "1", step: float = 10.0, booked: bool = False) -> None:  # fmt: skip
    """Drive `train` front first from `start` to `end` (up if end > start) in steps."""
    sense = 1.0 if end >= start else -1.0
    head = start
    while True:
        model.move(TrainPosition(train, head, head - sense * length, track, booked))
        if head == end:
            return
        head = min(head + step, end) if sense > 0 else max(head - step, end)


def kinds(events: list[RailEvent]) -> list[str]:
    return [e.kind for e in events]


@pytest.mark.requirement("TC-RAILS-01")
def test_facing_normal_runs_onto_the_main_track(line: Line) -> None:
    model = TrackCircuitModel(line)
    run(model, "T1", 400, 900)
    assert occupied(model) == {"TC1855"}
    assert model.track_of("T1") == "1" and model.under_antenna("T1") == "TC1855"
    assert model.take_events() == []


@pytest.mark.requirement("TC-RAILS-01")
def test_facing_reverse_runs_into_the_loop_whatever_track_it_was_put_on(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(18, {"31": "reverse"})
    run(model, "T1", 400, 900, track="1")  # put on "track 1" on the plain line: the blades rule
    assert occupied(model) == {"TC1856"}
    assert model.track_of("T1") == "2" and model.under_antenna("T1") == "TC1856"
    assert model.take_events() == []


def test_a_train_straddling_a_point_occupies_both_sides_on_its_own_track(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(18, {"31": "reverse"})
    run(model, "T1", 400, 640, length=100)
    assert occupied(model) == {"TC1853A", "TC1856"}
    # the tail follows the head's path: backing out, it is on the loop until the point
    for head in range(630, 550, -10):  # backing: the head stays its front end, up
        model.move(TrainPosition("T1", head, head - 100))
        assert model.track_of("T1") == "2"
    assert occupied(model) == {"TC1853A", "TC1851"}
    assert model.take_events() == []


@pytest.mark.requirement("TC-RAILS-02")
def test_trailing_against_the_blades_trails_the_point(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.move(TrainPosition("T2", 800, 840, "2"))  # a down train on the loop, 31 lies normal
    run(model, "T2", 800, 400, track="2")
    events = model.take_events()
    assert kinds(events) == ["trailed"]
    e = events[0]
    assert (e.station, e.point, e.leg, e.train) == (18, "31", "reverse", "T2")
    assert e.text.startswith("trailed point 18 31")
    assert model.blades[(18, "31")] == "reverse"  # forced over by the wheels
    assert occupied(model) == {"TC1851"}
    assert not model.derailed("T2")


def test_a_down_train_on_the_loop_trails_a_point_set_for_it(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(18, {"31": "reverse"})
    model.move(TrainPosition("T2", 800, 840, "2"))
    assert occupied(model) == {"TC1856"}
    run(model, "T2", 800, 580, track="2")
    assert occupied(model) == {"TC1853A", "TC1856"}
    run(model, "T2", 580, 300, track="2")
    assert occupied(model) == {"TC1851"}
    assert model.take_events() == []
    assert model.track_of("T2") is None  # the plain line


@pytest.mark.requirement("TC-RAILS-03")
def test_blades_moving_under_a_train_derail_it(line: Line) -> None:
    model = TrackCircuitModel(line)
    run(model, "T1", 400, 580)  # astride point 31 (normal)
    model.set_blades(18, {"31": "moving"})
    events = model.take_events()
    assert kinds(events) == ["derailed"]
    assert events[0].text.startswith("derailed 18 31") and model.derailed("T1")
    model.set_blades(18, {"31": "reverse"})
    assert model.take_events() == []  # once


@pytest.mark.requirement("TC-RAILS-03")
def test_a_train_meeting_moving_blades_facing_is_derailed(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(18, {"31": "moving"})
    run(model, "T1", 400, 560)
    assert kinds(model.take_events()) == ["derailed"]


def test_a_point_moved_once_the_train_is_clear_of_it_derails_nothing(line: Line) -> None:
    model = TrackCircuitModel(line)
    run(model, "T1", 400, 700)  # tail at 660: clear of 31
    model.set_blades(18, {"31": "moving"})
    model.set_blades(18, {"31": "reverse"})
    assert model.take_events() == []


def test_a_booked_train_off_its_track_is_misrouted(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(18, {"31": "reverse"})
    run(model, "1001", 400, 540, booked=True)
    assert model.take_events() == []  # before the point its booked track does not run yet
    run(model, "1001", 540, 700, booked=True)
    events = model.take_events()
    assert kinds(events) == ["misrouted"] and events[0].track == "2"
    assert events[0].text.startswith("misrouted")
    run(model, "1001", 700, 900, booked=True)
    assert model.take_events() == []  # once


def test_a_train_cannot_be_put_where_its_track_does_not_run(line: Line) -> None:
    model = TrackCircuitModel(line)
    with pytest.raises(ValueError, match="no track '3'"):
        model.move(TrainPosition("T1", 800, 760, "3"))
    assert model.trains == {} and occupied(model) == set()


def test_st20_the_third_track_is_reached_over_two_facing_points(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(20, {"31": "normal", "33": "reverse"})
    run(model, "T1", 5900, 6500, length=100)
    assert occupied(model) == {"TC2054"} and model.track_of("T1") == "3"
    model.set_blades(20, {"34": "normal"})  # lies for track 1: the train trails it from 3
    run(model, "T1", 6500, 7050, length=100)
    assert [(e.kind, e.point) for e in model.take_events()] == [("trailed", "34")]
    assert occupied(model) == {"TC2057A", "TC2061A"}


def test_st22_the_siding_is_beside_the_plain_line(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.set_blades(22, {"31": "reverse", "33": "reverse"})
    run(model, "T1", 11900, 12880, length=60)
    assert occupied(model) == {"TC2254"}  # the siding: not TC2261 of the plain line beside it
    assert model.take_events() == []


# -- a property: wherever the blades were, the train is where they sent it -------------------------

POSITIONS = ("normal", "reverse", "moving")
FACING = {"up": "31", "down": "32"}  # the point an up (down) train meets facing at station 18
TRAILING = {"up": "32", "down": "31"}
AT = {"31": 550.0, "32": 1150.0}
LEG = {"normal": "TC1855", "reverse": "TC1856"}


@settings(max_examples=150, deadline=None)
@given(
    direction=st.sampled_from(("up", "down")),
    length=st.floats(20.0, 300.0),
    moves=st.lists(
        st.tuples(
            st.floats(0.0, 60.0), st.sampled_from(("31", "32")), st.sampled_from((*POSITIONS, None))
        ),
        min_size=1,
        max_size=80,
    ),  # fmt: skip
)
def test_the_occupied_circuits_are_one_path_the_blades_gave(
    direction: str, length: float, moves: list[tuple[float, str, str | None]]
) -> None:
    """A train runs through station 18 by random steps while its points are thrown at random
    (moving included). Always: its occupied circuits are one connected path (one circuit at each
    place under it); in the station it is on the track 31's (32's) blades gave it when its front
    passed facing (moving: derailed there); a trailing point it passes lying for the other leg is
    trailed (moving: derailed); blades leaving its leg under it derail it, once per point."""
    model = TrackCircuitModel(LINE)
    sense = 1.0 if direction == "up" else -1.0
    head = 300.0 if direction == "up" else 1400.0
    blades = {"31": "normal", "32": "normal"}
    facing, trailing = FACING[direction], TRAILING[direction]
    leg: str | None = None  # the leg the facing point's blades gave the front
    derailed: set[str] = set()

    def expect(got: list[RailEvent], want: dict[str, str]) -> None:
        assert sorted((e.point or "", e.kind) for e in got) == sorted(want.items())
        derailed.update(p for p, k in want.items() if k == "derailed")

    model.move(TrainPosition("T", head, head - sense * length))
    for step, point, throw in moves:
        lo, hi = sorted((head, head - sense * length))
        if throw is not None:
            blades[point] = throw
            model.set_blades(18, {point: throw})
            under = leg is not None and lo < AT[point] < hi  # the front is past it, the tail not
            wrong = under and throw != leg and point not in derailed
            expect(model.take_events(), {point: "derailed"} if wrong else {})
        new = head + sense * step
        want: dict[str, str] = {}
        if (new - AT[facing]) * sense >= 0 > (head - AT[facing]) * sense:  # the front passes
            leg = blades[facing] if blades[facing] != "moving" else "normal"
            if blades[facing] == "moving":
                want[facing] = "derailed"
        if (new - AT[trailing]) * sense >= 0 > (head - AT[trailing]) * sense and leg is not None:
            lay = blades[trailing]
            if lay == "moving":
                want[trailing] = "derailed"
            elif lay != leg:
                want[trailing] = "trailed"
                blades[trailing] = leg  # forced over
        head = new
        model.move(TrainPosition("T", head, head - sense * length))
        lo, hi = sorted((head, head - sense * length))
        for p in ("31", "32"):  # a point under it left lying for another leg derails it
            if p not in want and p not in derailed and leg is not None and lo < AT[p] < hi:
                if blades[p] != leg and want.get(p) != "trailed":
                    want[p] = "derailed"
        expect(
            model.take_events(),
            {p: k for p, k in want.items() if p not in derailed or k == "trailed"},
        )
        _assert_one_path(model, head, head - sense * length)
        occ = occupied(model)
        if leg is not None and lo < 1100 and hi > 600:
            assert LEG[leg] in occ
            assert LEG["reverse" if leg == "normal" else "normal"] not in occ


def _assert_one_path(model: TrackCircuitModel, head: float, tail: float) -> None:
    """One occupied circuit at each sampled place under the train, none beyond it."""
    lo, hi = min(head, tail), max(head, tail)
    occ = [t for t in model.tcs if model.occupancy()[t.name]]
    for i in range(1, 10):
        x = lo + (hi - lo) * i / 10
        if any(abs(x - b) < 1e-6 for t in model.tcs for b in (t.from_m, t.to_m)):
            continue
        assert len([t for t in occ if t.from_m < x < t.to_m]) == 1, (x, [t.name for t in occ])
    assert all(t.from_m < hi and t.to_m > lo for t in occ)
