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


def test_verify_explores_within_the_bound_given_and_prints_it() -> None:
    done = cli("ixl", "verify", "--bound", "requests=1", "--station", "18")
    assert done.returncode == 0, done.stderr
    assert "campaign depth=40,requests=1," in done.stdout
    assert "station 18:" in done.stdout and "states/s" in done.stdout
    assert "no violation(s)" in done.stdout
    doc = json.loads(cli("ixl", "verify", "--bound", "requests=1", "--station", "18",
                         "--json").stdout)  # fmt: skip
    assert doc["bound"] == ["depth=40,requests=1,points=0,modes=0,trains=0,faults=0,env=0,"
                            "states=200000"]  # fmt: skip
    assert doc["stations"]["18"]["states"] == doc["states"] > 10
    bad = cli("ixl", "verify", "--bound", "requests=many")
    assert bad.returncode == 2 and "bad --bound" in bad.stderr
    unknown = cli("ixl", "verify", "--station", "99")
    assert unknown.returncode == 2 and "no station 99" in unknown.stderr
