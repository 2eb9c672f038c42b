"""Reference station/line data loads and every malformed variant gives a precise ConfigError."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from ktcs_bench.errors import ConfigError
from ktcs_bench.station import load_line
from ktcs_bench.station.loader import default_line_path


def test_reference_line_is_a_realistic_small_line() -> None:
    line = load_line()
    assert sorted(line.stations) == [18, 20, 22]
    for st in line.stations.values():
        assert 2 <= len(st.tracks) <= 3
        assert 2 <= len(st.points) <= 4
        kinds = {(s.kind, s.direction) for s in st.signals}
        for kind in ("home", "starting"):
            for d in ("up", "down"):
                assert (kind, d) in kinds, (st.number, kind, d)
        for p in st.points:
            assert p.throw_time_s == 4
        for t in st.track_circuits:
            assert t.name.startswith(f"TC{st.number}")
    names = [t.name for t in line.all_track_circuits()]
    assert len(names) == len(set(names))
    assert {"TC1853A", "TC1861A", "TC1863", "TC1867"} <= set(names)  # seed 004 Table 2
    assert [c.kmh for c in line.speed_codes][:5] == [0, 30, 45, 65, 80]
    assert any(s.kind == "shunt" for s in line.station(22).signals)


def test_every_approach_belongs_to_its_station() -> None:
    line = load_line()
    for number, st in line.stations.items():
        own = {t.name for t in line.view(number).track_circuits}
        for r in st.routes:
            assert set(r.approach) <= own, r.name


@pytest.fixture()
def copy(tmp_path: Path) -> Path:
    """A copy of the shipped line and stations; returns the copied line file."""
    src = default_line_path().parent.parent
    shutil.copytree(src / "lines", tmp_path / "lines")
    shutil.copytree(src / "stations", tmp_path / "stations")
    return tmp_path / "lines" / "reference.yaml"


def _edit(path: Path, change: Callable[[Any], None]) -> None:
    data = yaml.safe_load(path.read_text())
    change(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


def _set(data: Any, keys: list[Any], value: Any) -> None:
    for k in keys[:-1]:
        data = data[k]
    data[keys[-1]] = value


STATION_CASES: list[tuple[str, Callable[[Any], None], str, str]] = [
    (
        "unknown point in a route",
        lambda d: _set(d, ["routes", 3, "points", 0, "point"], "99"),
        "routes[3].points[0].point",
        "unknown point '99'",
    ),
    (
        "unknown track circuit in a route",
        lambda d: _set(d, ["routes", 0, "track_circuits", 1], "TC2099"),
        "routes[0].track_circuits[1]",
        "unknown track circuit 'TC2099'",
    ),
    (
        "duplicate track circuit",
        lambda d: _set(d, ["track_circuits", 1, "name"], "TC2053A"),
        "track_circuits[1].name",
        "duplicate track circuit 'TC2053A' (also track_circuits[0])",
    ),
    (
        "duplicate signal",
        lambda d: _set(d, ["signals", 2, "name"], "01"),
        "signals[2].name",
        "duplicate signal '01'",
    ),
    (
        "missing entry signal",
        lambda d: d["routes"][2].pop("entry"),
        "routes[2].entry",
        "missing key",
    ),
    (
        "wrong type",
        lambda d: _set(d, ["points", 0, "throw_time_s"], "fast"),
        "points[0].throw_time_s",
        "must be a number, not str",
    ),
    (
        "unknown point position",
        lambda d: _set(d, ["routes", 1, "points", 0, "position"], "left"),
        "routes[1].points[0].position",
        "must be one of normal, reverse",
    ),
    (
        "unknown aspect",
        lambda d: _set(d, ["signals", 0, "aspects"], ["R", "Z"]),
        "signals[0].aspects[1]",
        "unknown aspect 'Z'",
    ),
    (
        "release sections disagree with the route",
        lambda d: _set(
            d, ["routes", 0, "release_sections"], [["TC2053B"], ["TC2053A"], ["TC2055"]]
        ),
        "routes[0].release_sections",
        "must list the route's track circuits in order",
    ),
    (
        "conflict not mutual",
        lambda d: _set(d, ["routes", 0, "conflicts"], d["routes"][0]["conflicts"][1:]),
        "routes[1].conflicts[0]",
        "route '0111' does not list '0112' back as conflicting",
    ),
    (
        "shared track circuit not declared conflicting",
        lambda d: [_set(d, ["routes", i, "conflicts"], []) for i in range(len(d["routes"]))],
        "routes[0].conflicts",
        "shares",
    ),
    (
        "route exit facing the other way",
        lambda d: _set(d, ["routes", 0, "exit"], "21"),
        "routes[0].exit",
        "faces the other way",
    ),
    (
        "point outside its route's track circuits",
        lambda d: _set(d, ["routes", 0, "points", 0, "point"], "32"),
        "routes[0].points[0].point",
        "not among the track circuits",
    ),
    (
        "unknown approach track circuit",
        lambda d: _set(d, ["routes", 0, "approach"], ["TC9999"]),
        "routes[0].approach[0]",
        "unknown track circuit 'TC9999'",
    ),
    (
        "point leg to a track the station lacks",
        lambda d: _set(d, ["points", 0, "reverse"], "9"),
        "points[0].reverse",
        "unknown track '9'",
    ),
    (
        "point facing no direction",
        lambda d: _set(d, ["points", 0, "facing"], "left"),
        "points[0].facing",
        "must be one of up, down",
    ),
    (
        "point legs the other way round from the routes",
        lambda d: [_set(d, ["points", 0, "normal"], "2"), _set(d, ["points", 0, "reverse"], "1")],
        "routes[0].exit",
        "route 0111: the points as the route sets them lead to track 2, not signal 11's track 1",
    ),
    (
        "point toe on a track the routes do not reach it by",
        lambda d: _set(d, ["points", 2, "toe"], "2"),
        "routes[0].points",
        "route 0111: sets point 33 it never runs over",
    ),
    (
        "routes not a list",
        lambda d: _set(d, ["routes"], {"a": 1}),
        "routes",
        "must be a list, not dict",
    ),
]


@pytest.mark.parametrize(
    ("change", "place", "problem"),
    [c[1:] for c in STATION_CASES],
    ids=[c[0] for c in STATION_CASES],
)
def test_malformed_station_names_file_place_and_problem(
    copy: Path, change: Callable[[Any], None], place: str, problem: str
) -> None:
    station = copy.parent.parent / "stations" / "st20.yaml"
    _edit(station, change)
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(station)
    assert err.value.place == place
    assert problem in err.value.problem
    assert str(station) in str(err.value) and place in str(err.value)


LINE_CASES: list[tuple[str, Callable[[Any], None], str, str]] = [
    (
        "interval names an unknown track circuit",
        lambda d: _set(d, ["intervals", 1, "track_circuits", 0], "TC1899"),
        "intervals[1].track_circuits[0]",
        "unknown track circuit 'TC1899'",
    ),
    (
        "no stop code",
        lambda d: _set(d, ["atc", "codes"], [{"code": 1, "kmh": 30}]),
        "atc.codes",
        "needs a stop code",
    ),
    (
        "duplicate speed code",
        lambda d: d["atc"]["codes"].append({"code": 3, "kmh": 70}),
        "atc.codes[7].code",
        "duplicate code 3",
    ),
    (
        "plain track circuit owned by an unknown station",
        lambda d: _set(d, ["track_circuits", 0, "station"], 17),
        "track_circuits[0].station",
        "unknown station 17",
    ),
    (
        "track circuit ends before it starts",
        lambda d: _set(d, ["track_circuits", 2, "to_m"], 100),
        "track_circuits[2].to_m",
        "must be beyond from_m",
    ),
    (
        "gradient is text",
        lambda d: _set(d, ["gradients", 0, "permille"], "steep"),
        "gradients[0].permille",
        "must be a number",
    ),
]


@pytest.mark.parametrize(
    ("change", "place", "problem"),
    [c[1:] for c in LINE_CASES],
    ids=[c[0] for c in LINE_CASES],
)
def test_malformed_line_names_file_place_and_problem(
    copy: Path, change: Callable[[Any], None], place: str, problem: str
) -> None:
    _edit(copy, change)
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(copy)
    assert err.value.place == place
    assert problem in err.value.problem


def test_track_circuit_duplicated_between_line_and_station(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st18.yaml"
    extra = {"name": "TC1863", "from_m": 2000, "to_m": 2800}
    _edit(station, lambda d: d["track_circuits"].append(extra))
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(station)
    assert err.value.place == "track_circuits[4].name"
    assert "duplicate track circuit 'TC1863'" in err.value.problem


def test_station_number_disagreeing_with_line(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st22.yaml"
    _edit(station, lambda d: _set(d, ["station"], 24))
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.place == "station" and "lists it as 22" in err.value.problem


def test_yaml_syntax_error_gives_line_and_column(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st18.yaml"
    station.write_text("station: 18\ntracks: [1, 2\n")
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(station)
    assert err.value.place.startswith("line ")


def test_missing_station_file(copy: Path) -> None:
    (copy.parent.parent / "stations" / "st20.yaml").unlink()
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert "cannot read" in err.value.problem


def test_a_line_is_loaded_once_until_one_of_its_files_changes(copy: Path) -> None:
    """Every device process loads its lab's line (the lab file's check, then the device): the
    second load is the first one's Line. A station file rewritten at once, same size (so within
    one clock tick its modification time may not move), is read again."""
    first = load_line(copy)
    assert load_line(copy) is first
    station = copy.parent.parent / "stations" / "st20.yaml"
    text = station.read_text(encoding="utf-8")
    station.write_text(text.replace("name: Station 20", "name: Station 2X"), encoding="utf-8")
    second = load_line(copy)
    assert second is not first
    assert second.station(20).name == "Station 2X"
    assert first.station(20).name == "Station 20"
    assert load_line(copy) is second
