"""The scenario file's shape is declared (`scenario/shapes.py`): bounds, defaults and the one
number that may be infinite are written once, and a file that does not fit is one ConfigError
naming the key path and its line."""

from __future__ import annotations

from pathlib import Path

import pytest

from ktcs_bench.errors import ConfigError
from ktcs_bench.scenario.model import Scenario, load_scenario

BASE = """\
name: t
duration_s: 120
line:
  length_m: 3000
  tags: {spacing_m: 100}
  protection_zones: [{from_m: 1500, to_m: 1600, active_until_s: .inf}]
trains:
  - {id: A, start_m: 300, driver_speed_kmh: 60}
"""


def _load(tmp_path: Path, text: str) -> Scenario:
    path = tmp_path / "s.yaml"
    path.write_text(text, encoding="utf-8")
    return load_scenario(path)


def test_defaults_come_from_the_shape_and_a_zone_may_last_for_ever(tmp_path: Path) -> None:
    s = _load(tmp_path, BASE)
    assert s.dt == 0.1 and s.name == "t" and s.zones[0].active_until == float("inf")
    train = s.trains[0]
    assert train.params.length == 200.0 and train.eb_release_delay == 5.0
    assert len(s.line.tags) == 31  # every 100 m over 3000 m, both ends


@pytest.mark.parametrize(
    ("old", "new", "place", "problem"),
    [
        ("start_m: 300", "start_m: 300, length_m: 0.5", "trains[0].length_m", "must be at least 1, got 0.5"),
        ("duration_s: 120", "duration_s: 100000", "duration_s", "must be at most 86400, got 100000"),
        ("active_until_s: .inf", "active_until_s: .nan", "line.protection_zones[0].active_until_s",
         "expected a finite number, got nan"),
        ("start_m: 300", "start_m: .inf", "trains[0].start_m", "expected a finite number, got inf"),
        ("tags: {spacing_m: 100}", "tags: {first_m: 5}", "line.tags.spacing_m", "missing"),
    ],
)  # fmt: skip
def test_a_value_out_of_its_bounds_is_one_error_with_its_line(
    tmp_path: Path, old: str, new: str, place: str, problem: str
) -> None:
    text = BASE.replace(old, new, 1)
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, text)
    assert err.value.place == place
    line = next(i for i, x in enumerate(text.splitlines(), 1) if new in x)
    assert err.value.problem == f"{problem} (line {line})", err.value.problem
