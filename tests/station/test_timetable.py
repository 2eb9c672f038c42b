"""The reference timetable loads with the routes each call needs, and every malformed variant is
one ConfigError naming the file, the key path and the problem."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.station import load_line
from ktcs_bench.station.generate import line_files
from ktcs_bench.station.timetable import load_timetable

LINE = load_line()
REFERENCE = data_dir("emulators") / "timetables" / "reference.yaml"


def test_the_reference_timetable_runs_two_seed001_trains_18_20_22_and_one_back() -> None:
    tt = load_timetable(REFERENCE, LINE)
    assert [t.id for t in tt.trains] == ["1001", "1003", "2001"]
    first, second, down = tt.trains
    for t in (first, second):  # seed 001 Table 1
        d = t.data
        assert (d.length_m, d.max_speed_kmh, t.direction) == (200.0, 80.0, "up")
        assert (d.traction_kmh_per_s, d.service_brake_kmh_per_s, d.emergency_brake_kmh_per_s) == (
            3.0,
            3.0,
            4.0,
        )
        assert [s.station for s in t.stops] == [18, 20, 22]
        assert t.appears_on == "TC1851" and not t.leaves_lab
        assert all(s.dwell_s > 0 for s in t.stops)
    assert second.enters_at_s > first.enters_at_s  # the second follows the first
    assert [(s.home_route, s.start_route) for s in first.stops] == [
        ("0111", "1191"),
        ("0111", "1191"),
        ("0111", None),
    ]
    assert second.stops[-1].track == "2" and second.stops[-1].home_route == "0112"
    # the down train, 22 -> 20 -> 18, waits for the up trains in station 20's loop (track 2)
    assert (down.data, down.direction, down.appears_on) == (first.data, "down", "TC2261")
    assert [(s.station, s.track) for s in down.stops] == [(22, "1"), (20, "2"), (18, "1")]
    assert [(s.home_route, s.start_route) for s in down.stops] == [
        ("0221", "2192"),
        ("0222", "2292"),
        ("0221", None),
    ]


def test_the_timetable_line_generate_writes_loads_too(tmp_path: Path) -> None:
    """One format: the generated line's timetable (trains standing at their first stop)."""
    files = line_files(3)
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text, encoding="utf-8")
    line = load_line(tmp_path / "line.yaml")
    tt = load_timetable(tmp_path / "timetable.yaml", line)
    t1, t2 = tt.trains
    assert (t1.enters, t2.depart_s) == (None, 180.0)
    assert t1.stops[0].home_route is None and t1.stops[0].start_route is not None
    assert t1.appears_on.endswith("55") and t2.appears_on.endswith("56")  # on their platforms


def bad(tmp_path: Path, change: Callable[[Any], None]) -> ConfigError:
    data = yaml.safe_load(REFERENCE.read_text(encoding="utf-8"))
    data["line"] = str(Path(LINE.file).resolve())
    change(data)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_timetable(path, LINE)
    assert err.value.file == str(path)
    return err.value


def stop(i: int, **changes: object) -> Callable[[Any], None]:
    def change(d: Any) -> None:
        d["trains"][0]["stops"][i].update(changes)

    return change


def train(**changes: object) -> Callable[[Any], None]:
    def change(d: Any) -> None:
        d["trains"][0].update(changes)

    return change


@pytest.mark.parametrize(
    ("change", "place", "problem"),
    [
        (stop(1, station=21), "trains[0].stops[1].station", "station 21 is not on the line"),
        (stop(1, track="4"), "trains[0].stops[1].track", "station 20 has no track '4'"),
        (stop(0, dwell_s=-1), "trains[0].stops[0].dwell_s", "must be a finite number >= 0"),
        (stop(0, dwell_s="long"), "trains[0].stops[0].dwell_s", "must be a number"),
        (
            stop(1, station=22, stop_m=12680),
            "trains[0].stops[1].station",
            "reaches station 20, not 22",
        ),
        (
            stop(0, stop_m=700),
            "trains[0].stops[0].stop_m",
            "a 200 m train stopping at 700 m does not stand wholly on track 1's circuit TC1855",
        ),
        (
            train(enters={"track_circuit": "TC1863"}),
            "trains[0].enters.track_circuit",
            "TC1863 is not on the approach to station 18",
        ),
        (train(direction="sideways"), "trains[0].direction", "must be one of up, down"),
        (train(train="tgv"), "trains[0].train", "no train data 'tgv' under train_data"),
        (
            lambda d: d["train_data"]["seed001-table1"].update(length_m=0),
            "train_data.seed001-table1.length_m",
            "must be positive",
        ),
        (
            train(enters={"track_circuit": "TC9999"}),
            "trains[0].enters.track_circuit",
            "no track circuit 'TC9999'",
        ),
        (train(stops=[]), "trains[0].stops", "stops at one station at least"),
        (train(leaves_lab="yes"), "trains[0].leaves_lab", "must be true or false"),
        (lambda d: d["trains"][1].update(id="1001"), "trains[1].id", "duplicate train '1001'"),
        (lambda d: d.pop("trains"), "trains", "missing key"),
        (lambda d: d.update(line="../lines/other.yaml"), "line", "the timetable runs on"),
    ],
)
def test_a_bad_timetable_names_file_place_and_problem(
    tmp_path: Path, change: Callable[[Any], None], place: str, problem: str
) -> None:
    err = bad(tmp_path, change)
    assert err.place == place
    assert problem in err.problem


def test_a_key_given_twice_is_refused_with_its_line(tmp_path: Path) -> None:
    text = REFERENCE.read_text(encoding="utf-8").replace(
        "    direction: up\n", "    direction: up\n    direction: down\n", 1
    )
    text = text.replace("line: ../lines/reference.yaml", f"line: {Path(LINE.file).resolve()}")
    path = tmp_path / "twice.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_timetable(path, LINE)
    assert "duplicate key 'direction'" in str(err.value) and str(path) in str(err.value)


def test_a_key_nobody_reads_is_refused_with_its_line(tmp_path: Path) -> None:
    """The timetable's shape is declared: a misspelt key is not silently ignored."""
    text = REFERENCE.read_text(encoding="utf-8").replace(
        "    direction: up\n", "    direction: up\n    dwel_s: 30\n", 1
    )
    text = text.replace("line: ../lines/reference.yaml", f"line: {Path(LINE.file).resolve()}")
    path = tmp_path / "misspelt.yaml"
    path.write_text(text, encoding="utf-8")
    line = text.splitlines().index("    dwel_s: 30") + 1
    with pytest.raises(ConfigError) as err:
        load_timetable(path, LINE)
    assert err.value.file == str(path)
    assert err.value.place == "trains[0].dwel_s"
    assert err.value.problem == f"unknown key (line {line})"


def test_train_data_of_the_wrong_type_names_its_key_and_line(tmp_path: Path) -> None:
    text = REFERENCE.read_text(encoding="utf-8")
    text = text.replace("line: ../lines/reference.yaml", f"line: {Path(LINE.file).resolve()}")
    assert "max_speed_kmh: 80," in text
    text = text.replace("max_speed_kmh: 80,", "max_speed_kmh: fast,", 1)
    path = tmp_path / "fast.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_timetable(path, LINE)
    assert err.value.place == "train_data.seed001-table1.max_speed_kmh"
    line = next(i for i, x in enumerate(text.splitlines(), 1) if "max_speed_kmh: fast" in x)
    assert err.value.problem == f"must be a number, not str (line {line})"
