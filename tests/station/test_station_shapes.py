"""The station and line files' shapes are declared (`station/shapes.py`): a key nobody reads is
refused, and a value of the wrong type is one message naming the file, the key path and the
line it is on -- from the text as the user wrote it, comments and all."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ktcs_bench.errors import ConfigError
from ktcs_bench.station import load_line
from ktcs_bench.station.loader import default_line_path


@pytest.fixture()
def copy(tmp_path: Path) -> Path:
    src = default_line_path().parent.parent
    shutil.copytree(src / "lines", tmp_path / "lines")
    shutil.copytree(src / "stations", tmp_path / "stations")
    return tmp_path / "lines" / "reference.yaml"


def _number_of(path: Path, text: str) -> int:
    """The line number of `path` that holds `text`."""
    return next(i for i, x in enumerate(path.read_text().splitlines(), 1) if text in x)


def _replace(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


def test_unknown_key_in_a_station_file_is_refused_with_its_line(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st20.yaml"
    _replace(
        station, 'to_m: 6900, tracks: ["2"]}', 'to_m: 6900, tracks: ["2"],\n     colour: blue}'
    )
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(station)
    assert err.value.place == "track_circuits[4].colour"
    assert err.value.problem == f"unknown key (line {_number_of(station, 'colour: blue')})"


def test_wrong_type_in_the_line_file_names_key_path_and_line(copy: Path) -> None:
    _replace(copy, "service_brake_mps2: 0.5", "service_brake_mps2: [0.5]")
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.file == str(copy)
    assert err.value.place == "atc.service_brake_mps2"
    line = _number_of(copy, "service_brake_mps2: [0.5]")
    assert err.value.problem == f"must be a number, not list (line {line})"


def test_missing_key_names_the_mapping_that_lacks_it(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st18.yaml"
    _replace(station, '{name: "32", track_circuits: [TC1857A], position_m: 1150,',
             '{name: "32", track_circuits: [TC1857A],')  # fmt: skip
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.place == "points[1].position_m"
    line = _number_of(station, '{name: "32"')
    assert err.value.problem == f"missing key (line {line})"


def test_cli_gives_one_message_and_exit_2(copy: Path) -> None:
    station = copy.parent.parent / "stations" / "st22.yaml"
    _replace(station, "station: 22", "station: twenty-two")
    out = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "chart", "generate", "--line", str(copy),
         "--out", str(copy.parent.parent / "charts")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    line = _number_of(station, "station: twenty-two")
    assert f"{station}: station: must be an integer, not str (line {line})" in out.stderr
    assert out.stderr.count("\n") == 1, out.stderr


def test_a_reference_check_names_the_line_too(copy: Path) -> None:
    """Past the shape, the checks in code (here an unknown track circuit) give the line of the
    key path they name, looked up in the file as written."""
    station = copy.parent.parent / "stations" / "st18.yaml"
    _replace(
        station, '{name: "32", track_circuits: [TC1857A]', '{name: "32", track_circuits: [TC1899]'
    )
    with pytest.raises(ConfigError) as err:
        load_line(copy)
    assert err.value.place == "points[1].track_circuits[0]"
    line = _number_of(station, "[TC1899]")
    assert err.value.problem == f"unknown track circuit 'TC1899' (line {line})"
