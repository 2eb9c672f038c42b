"""Point geometry (SPEC §6.7): where each station track runs, and `chart check`'s check of the
geometry against the routes."""

from __future__ import annotations

from dataclasses import replace

import pytest

from ktcs_bench.chart_files.check import check_point_geometry
from ktcs_bench.station import Line, load_line
from ktcs_bench.station.geometry import LineGeometry, meets, track_extent


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


def test_tracks_run_between_the_points_that_lead_to_them(line: Line) -> None:
    assert track_extent(line.station(18), "2") == (550, 1150)
    assert track_extent(line.station(20), "3") == (6150, 6850)  # behind 33 and 34
    assert track_extent(line.station(22), "3") == (12650, 12900)  # a siding: to its buffer stop


def test_a_train_meets_a_point_only_on_the_track_its_side_names(line: Line) -> None:
    p33 = line.station(20).point("33")  # toe on track 1 facing up, legs 1 and 3
    assert meets(p33, "1", upward=True) == "toe"
    assert meets(p33, "2", upward=True) is None  # the loop runs past it
    assert meets(p33, "3", upward=False) == "reverse"
    assert meets(p33, "1", upward=False) == "normal"


def test_where_a_train_is_put(line: Line) -> None:
    g = LineGeometry(line)
    assert g.track_at(300, "1") is None  # the plain line
    assert g.track_at(800, "2") == "2"
    assert g.track_at(12850, "1") is None  # beyond st22's last point: the plain line
    assert g.track_at(12850, "3") == "3"  # ... beside the siding
    with pytest.raises(ValueError, match="no track '3' at 6100 m in station 20"):
        g.track_at(6100, "3")


def test_chart_check_finds_the_reference_geometry_consistent(line: Line) -> None:
    assert check_point_geometry(line) == []


def test_chart_check_names_a_route_whose_circuits_the_geometry_does_not_give(line: Line) -> None:
    st = line.station(18)
    wrong = replace(st.routes[0], track_circuits=("TC1853A", "TC1856"))  # 0111 over 31 normal
    bad = replace(line, stations={**line.stations, 18: replace(st, routes=(wrong, *st.routes[1:]))})
    problems = check_point_geometry(bad)
    assert problems == [
        f"{st.file}: routes[0].track_circuits: route 0111 lists ['TC1853A', 'TC1856'], its "
        "points as they are set run over ['TC1853A', 'TC1855']"
    ]


def test_chart_check_names_a_point_whose_legs_contradict_a_route(line: Line) -> None:
    st = line.station(18)
    p31 = replace(st.point("31"), normal="2", reverse="1")
    bad = replace(line, stations={**line.stations, 18: replace(st, points=(p31, *st.points[1:]))})
    problems = check_point_geometry(bad)
    assert (
        f"{st.file}: routes[0].exit: route 0111: the points as the route sets them lead to "
        "track 2, not signal 11's track 1" in problems
    )
