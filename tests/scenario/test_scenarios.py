"""Scenario runs end to end: shipped scenarios pass, assertions fail when they should, bad files
are named precisely, the CLI's exit codes and report files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.scenario.assertions import check_all
from ktcs_bench.scenario.model import load_scenario
from ktcs_bench.scenario.runner import run

SCENARIOS = data_dir("emulators") / "scenarios"


@pytest.mark.parametrize(
    "name",
    ["seed001_eb_release", "seed001_protection_zone", "seed003_table3", "ato_station_stops"],
)
def test_shipped_scenario_passes(name: str) -> None:
    result = run(load_scenario(SCENARIOS / f"{name}.yaml"))
    outcomes = check_all(result)
    assert outcomes and all(o.passed for o in outcomes), [o.detail for o in outcomes]


def test_seed001_follower_keeps_its_distance_and_cli_writes_report(tmp_path: Path) -> None:
    rc = main(
        [
            "scenario",
            "run",
            str(SCENARIOS / "seed001_follower.yaml"),
            "--out",
            str(tmp_path),
            "--json",
        ]
    )
    assert rc == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["passed"] and summary["trains"]["T2"]["emergency_brakes"] == 0
    for f in ("speed_distance.png", "time_distance.png"):
        assert (tmp_path / f).stat().st_size > 0
    assert (tmp_path / "events.log").is_file()
    assert (tmp_path / "speed_distance.png").read_bytes()[:4] == b"\x89PNG"


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.yaml"
    p.write_text(text)
    return p


BASE = """
name: t
duration_s: 120
line: {length_m: 3000, tags: {spacing_m: 100},
       speed_limits: [{from_m: 0, to_m: 3000, speed_kmh: 60}],
       protection_zones: [{from_m: 1500, to_m: 1600}]}
trains: [{id: A, start_m: 300, driver_speed_kmh: 60}]
"""


def test_failing_assertion_gives_exit_1(tmp_path: Path) -> None:
    p = _write(tmp_path, BASE + "assertions: [{reaches: {train: A, location: 1700}}]\n")
    assert main(["scenario", "run", str(p), "--out", str(tmp_path / "r")]) == 1


def test_protection_zone_stops_the_train(tmp_path: Path) -> None:
    p = _write(tmp_path, BASE + "assertions: [{never_passes: {train: A, location: 1500}}]\n")
    assert main(["scenario", "run", str(p), "--out", str(tmp_path / "r")]) == 0


@pytest.mark.parametrize(
    ("patch", "place"),
    [
        ("trains: [{id: A, start_m: fast}]", "trains[0].start_m"),
        ("trains: [{id: A, start_m: 1, colour: red}]", "trains[0].colour"),
        ("trains: [{id: A, start_m: 1, mode: etcs}]", "trains[0].mode"),
        ("trains: [{id: A, start_m: .nan}]", "trains[0].start_m"),
        ("trains: [{id: A, start_m: .inf}]", "trains[0].start_m"),
        ("trains: [{id: A, start_m: 300, driver_speed_kmh: -.inf}]", "trains[0].driver_speed_kmh"),
    ],
)
def test_bad_train_is_one_config_error_naming_the_key(
    tmp_path: Path, patch: str, place: str
) -> None:
    text = BASE.replace("trains: [{id: A, start_m: 300, driver_speed_kmh: 60}]", patch)
    with pytest.raises(ConfigError) as exc:
        load_scenario(_write(tmp_path, text))
    assert exc.value.place == place
    assert str(tmp_path / "s.yaml") in str(exc.value)


def test_unknown_train_in_assertion_and_cli_exit_2(tmp_path: Path) -> None:
    p = _write(tmp_path, BASE + "assertions: [{never_passes: {train: Z, location: 1}}]\n")
    with pytest.raises(ConfigError) as exc:
        load_scenario(p)
    assert exc.value.place == "assertions[0].never_passes.train"
    assert main(["scenario", "run", str(p)]) == 2
    assert main(["scenario", "run", str(_write(tmp_path, "line: [unclosed"))]) == 2


KTCS = """
name: code-steps
duration_s: 400
stop_when_all_stopped: true
line:
  length_m: 3000
  tags: {spacing_m: 100}
  # no speed limit in the line data: a 30 km/h stretch [1400, 1800) and the stop point at 2800
  # are known from the codes alone (each code's speed holds at its track circuit's exit)
  track_circuits:
    - {id: TC1, from_m: 0, to_m: 1000, code_kmh: 80, target_distance_m: 2800}
    - {id: TC2, from_m: 1000, to_m: 1400, code_kmh: 30, target_distance_m: 1800}
    - {id: TC3, from_m: 1400, to_m: 1800, code_kmh: 30, target_distance_m: 1400}
    - {id: TC4, from_m: 1800, to_m: 2400, code_kmh: 80, target_distance_m: 1000}
    - {id: TC5, from_m: 2400, to_m: 2800, code_kmh: 0, target_distance_m: 400}
trains: [{id: T1, mode: ktcs, start_m: 150, length_m: 100, max_speed_kmh: 80}]
assertions:
  - max_speed: {train: T1, kmh: 30, from_m: 1400, to_m: 1800}
  - max_speed: {train: T1, kmh: 80}
  - reaches: {train: T1, location: 2700}
  - never_passes: {train: T1, location: 2800}
  - event: {train: T1, kind: emergency_brake, at_most: 0}
"""


def test_ktcs_code_speeds_hold_at_the_track_circuit_exits(tmp_path: Path) -> None:
    """The runner passes each code on as read; the train is down to 30 km/h by the exit of the
    circuit before the 30 stretch, without an emergency brake, and stops at the stop point."""
    result = run(load_scenario(_write(tmp_path, KTCS)))
    outcomes = check_all(result)
    assert all(o.passed for o in outcomes), [o.detail for o in outcomes]
    assert max(result.traces["T1"].speed) * 3.6 > 70.0  # it ran at line speed before the step


def test_max_speed_on_a_stretch_fails_when_exceeded(tmp_path: Path) -> None:
    text = KTCS.replace("{train: T1, kmh: 30, from_m: 1400", "{train: T1, kmh: 20, from_m: 1400")
    outcomes = check_all(run(load_scenario(_write(tmp_path, text))))
    assert [o.passed for o in outcomes] == [False, True, True, True, True]
    assert "on [1400, 1800) m" in outcomes[0].detail


@pytest.mark.parametrize("item", [".nan", "ten", "[1]"])
def test_a_bad_tag_position_is_one_config_error_naming_the_item(tmp_path: Path, item: str) -> None:
    text = BASE.replace("tags: {spacing_m: 100}", f"tags: {{at_m: [100, {item}]}}")
    with pytest.raises(ConfigError) as exc:
        load_scenario(_write(tmp_path, text))
    assert exc.value.place == "line.tags.at_m[1]"


def test_a_config_error_gives_the_line_of_its_key(tmp_path: Path) -> None:
    """The scenario's reader names the line the key path is on (BASE starts with a blank line)."""
    text = BASE.replace("trains: [{id: A, start_m: 300, driver_speed_kmh: 60}]",
                        "trains:\n  - {id: A, start_m: 1, colour: red}")  # fmt: skip
    with pytest.raises(ConfigError) as exc:
        load_scenario(_write(tmp_path, text))
    assert exc.value.place == "trains[0].colour"
    line = text.splitlines().index("  - {id: A, start_m: 1, colour: red}") + 1
    assert exc.value.problem.endswith(f"(line {line})"), exc.value.problem
