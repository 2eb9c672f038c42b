"""`ktcs-bench ixl table` and `ixl verify` as a user runs them (a real subprocess)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.cli.conftest import cli


def test_table_writes_a_csv_per_station_and_an_index(tmp_path: Path) -> None:
    done = cli("ixl", "table", "--out", str(tmp_path / "t"))
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == [
        "18.csv", "20.csv", "22.csv", "index.html",
    ]  # fmt: skip
    assert (tmp_path / "t" / "18.csv").read_text().startswith("route,entry,exit,")


def test_verify_data_only_json_is_clean_and_a_missing_line_is_bad_input(tmp_path: Path) -> None:
    done = cli("ixl", "verify", "--data-only", "--json")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert set(doc) >= {"states", "transitions", "bound", "seconds", "stations", "findings",
                        "violations"}  # fmt: skip
    assert doc["findings"] == [] and doc["violations"] == []
    bad = cli("ixl", "verify", str(tmp_path / "nope.yaml"))
    assert bad.returncode == 2 and "no line file" in bad.stderr
