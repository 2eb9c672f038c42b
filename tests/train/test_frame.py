"""The line as a train running one way sees it (`train.frame.Frame`): a down train's coordinate is
the chainage mirrored, there and back; a rise up is a fall down; each code's track circuit is
entered by the end the train meets first; and a down timetable train's onboard data -- its start,
its stops, its precision-stop tags -- lie in that frame."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ktcs_bench.emulator.train import (
    ENTRY_SHORT_M,
    PSM_M,
    TrainDevice,
    line_frame,
    timetable_run,
    train_line,
)
from ktcs_bench.errors import UsageError
from ktcs_bench.station import load_line
from ktcs_bench.station.timetable import load_timetable
from ktcs_bench.train.frame import Frame
from ktcs_bench.transport.endpoints import Endpoint

TIMETABLE = Path(__file__).parents[1] / "lab" / "down_train.yaml"  # 2001: 22 -> 20 -> 18
MARKS = {"22": 12120.0, "20": 6220.0, "18": 620.0}
LINE = load_line()
UP, DOWN = line_frame(LINE, "up"), line_frame(LINE, "down")
places = st.floats(-20000.0, 20000.0, allow_nan=False)


@given(places, st.floats(-500.0, 500.0), st.floats(1.0, 30000.0))
def test_there_and_back_is_the_place_itself_and_a_down_train_runs_against_the_chainage(
    x: float, start: float, length: float
) -> None:
    up, down = Frame(start, start + length, "up"), Frame(start, start + length, "down")
    assert up.s(x) == x and up.x(x) == x
    assert down.x(down.s(x)) == pytest.approx(x, abs=1e-9)
    assert down.s(down.x(x)) == pytest.approx(x, abs=1e-9)
    # the line's ends swap: the down train's line spans the same [start, end]
    assert down.s(start) == pytest.approx(start + length)
    assert down.s(start + length) == pytest.approx(start)
    # further down the line is further on for it
    assert down.s(x - 1.0) == pytest.approx(down.s(x) + 1.0)


def test_a_stretch_is_entered_by_the_end_the_train_meets_first() -> None:
    assert UP.span(6200.0, 6800.0) == (6200.0, 6800.0)
    assert DOWN.span(6200.0, 6800.0) == (13300.0 - 6800.0, 13300.0 - 6200.0)


def test_a_down_code_counts_its_target_distance_from_the_circuits_upper_end() -> None:
    # TC2055 (6200-6800 m, track 1 at 20): a down train stops 20 m short of signal 21 at 6200 m
    code = DOWN.code(6200.0, 6800.0, 10.0, -3.0, 580.0)
    assert (code.start, code.end) == (DOWN.s(6800.0), DOWN.s(6200.0))
    assert DOWN.x(code.target_point) == 6220.0
    assert code.gradient == -3.0  # the wayside grades it for the direction of travel already
    up = UP.code(6200.0, 6800.0, 10.0, 2.0, 580.0)
    assert (up.start, up.end, up.target_point) == (6200.0, 6800.0, 6780.0)
    # no stop point ahead: none in either frame
    assert math.isinf(DOWN.code(6200.0, 6800.0, 10.0, 0.0, None).target_point)


def test_the_reference_lines_rise_up_is_a_fall_for_a_down_train() -> None:
    up, down = train_line(LINE, UP).gradient, train_line(LINE, DOWN).gradient
    assert up.at(8000.0) == 15.0  # 7200-9000 m rises 15 ‰ up
    assert down.at(DOWN.s(8000.0)) == -15.0
    for x in range(5, 13300, 10):  # everywhere off the breakpoints, the same slope seen both ways
        assert down.at(DOWN.s(float(x))) == -up.at(float(x)), x
        assert up.at(float(x)) == LINE.gradient_between(x, x)


segments = st.lists(
    st.tuples(st.floats(0.0, 900.0), st.floats(1.0, 300.0), st.integers(-20, 20)),
    min_size=1,
    max_size=6,
)


@given(segments, st.floats(0.0, 1.0), st.floats(0.0, 500.0))
def test_any_gradient_table_reads_negated_at_the_mirrored_place_and_level_where_silent(
    raw: list[tuple[float, float, int]], where: float, beyond: float
) -> None:
    # non-overlapping stretches, with gaps between them and the line running on past the last
    table, at = [], 0.0
    for gap, length, g in raw:
        table.append((at + gap, at + gap + length, float(g)))
        at += gap + length
    end = at + beyond
    frame_up, frame_down = Frame(0.0, end, "up"), Frame(0.0, end, "down")
    up, down = frame_up.gradient(table), frame_down.gradient(table)
    x = where * end
    if any(abs(x - b) < 1e-6 for a, b_, _ in table for b in (a, b_)):
        return  # on a breakpoint: which side holds is a convention
    expected = next((g for a, b, g in table if a < x < b), 0.0)
    assert up.at(x) == expected
    assert down.at(frame_down.s(x)) == -expected


def test_speed_limits_and_tags_are_mirrored() -> None:
    onboard = train_line(LINE, DOWN)
    first = onboard.restrictions[0]  # 80 km/h over 0-1400 m up: the last 1400 m for a down train
    assert (first.start, first.end) == (13300.0 - 1400.0, 13300.0)
    assert onboard.tags == sorted(onboard.tags) and onboard.tags[0] == 0.0
    assert {DOWN.x(t) for t in onboard.tags} == set(train_line(LINE).tags)


def test_a_frame_is_a_line_run_one_way() -> None:
    with pytest.raises(UsageError, match="up or down"):
        Frame(0.0, 100.0, "sideways")  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="lower to a higher"):
        Frame(100.0, 100.0)


def test_a_down_timetable_train_starts_and_stops_in_its_own_frame() -> None:
    entry = load_timetable(TIMETABLE, LINE).train("2001")
    run = timetable_run(entry, LINE, 0.5)
    assert run.frame == DOWN
    # it comes on 50 m short of TC2261's lower end (12800 m), heading down
    assert run.frame.x(run.config.start) == 12800.0 + ENTRY_SHORT_M
    marks = {s.name: run.frame.x(s.stop_mark) for s in run.line.stations}
    assert marks == MARKS
    # the precision-stop markers lie before each mark as the train meets them: above it
    for mark in MARKS.values():
        for back in PSM_M:
            assert DOWN.s(mark + back) in run.line.tags
    # the station tracks it uses stay in chainage (the rails' picture)
    assert [(lo, hi, t) for lo, hi, t in run.tracks] == [
        (12000.0, 12900.0, "1"),
        (6000.0, 7000.0, "1"),
        (500.0, 1200.0, "1"),
    ]


def test_the_train_process_speaks_chainage_to_the_rails_for_a_down_train() -> None:
    """Its position on the rails: head at the lower end, leading; a code from the rails located
    from the circuit's upper end; gone off the line's low end once it has left."""
    run = timetable_run(load_timetable(TIMETABLE, LINE).train("2001"), LINE, 0.5)
    rails = Endpoint("tcp", "", "127.0.0.1", 9)  # never connected: nothing here runs
    device = TrainDevice("train2001", LINE, run.config, rails, run=run)
    assert device._position() == {"head": 12850.0, "tail": 13050.0, "track": "1"}
    # TC2255 (12100-12700 m, track 1 at 22): stop 20 m short of down starting signal 21
    device._from_rails({"code": [3, 45, -2.0, 580.0], "tc": "TC2255"})
    assert device.code is not None and device.code.speed == pytest.approx(45 / 3.6)
    assert DOWN.x(device.code.target_point) == 12120.0
    assert device.status()["code"] == [45.0, -2.0, 12120.0]
    device.endpoint.left = True  # off the end of its line: below the lab's west edge
    assert device._position() == {"head": -201.0, "tail": -1.0}
