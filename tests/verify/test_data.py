"""The data checks of `ixl verify` and the control tables: clean on the shipped and a generated
line, and each seeded defect found, named by station, route and element."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ktcs_bench.lab.generate import write_line
from ktcs_bench.station import load_line
from ktcs_bench.station.model import PointSetting
from ktcs_bench.verify.data import Finding, check_line
from ktcs_bench.verify.report import run_verify
from ktcs_bench.verify.table import COLUMNS, index_html, station_csv, write_tables
from tests.verify.seeds import reference, with_route, without_conflict


def found(findings: list[Finding], route: str, element: str, kind: str) -> bool:
    return any(f.route == route and f.element == element and f.kind == kind for f in findings)


def test_shipped_and_generated_lines_are_clean(tmp_path: Path) -> None:
    assert check_line(reference()) == []
    write_line(4, tmp_path / "line")
    generated = load_line(tmp_path / "line" / "line.yaml")
    assert check_line(generated) == []
    written = write_tables(generated, tmp_path / "tables")
    assert sorted(p.name for p in written) == ["12.csv", "14.csv", "16.csv", "18.csv", "index.html"]
    result = run_verify(generated, bound_text="requests=1", stations=[14])
    assert result["states"] > 10 and not result["findings"] and not result["violations"]


def test_a_track_circuit_dropped_from_a_route_is_found() -> None:
    line = with_route(reference(), 20, "0111", track_circuits=("TC2053A", "TC2055"))
    findings = check_line(line)
    assert found(findings, "0111", "TC2053B", "track_circuit"), findings
    assert all(f.station == 20 for f in findings)


def test_a_point_position_wrong_for_the_path_is_found() -> None:
    line = with_route(
        reference(), 20, "0113",
        points=(PointSetting("31", "normal"), PointSetting("33", "normal")),
    )  # fmt: skip
    findings = check_line(line)
    assert found(findings, "0113", "33", "position"), findings


def test_an_overlap_point_dropped_is_found() -> None:
    line = with_route(reference(), 20, "0111", overlap_points=())
    findings = check_line(line)
    assert found(findings, "0111", "34", "overlap"), findings


def test_a_conflict_removed_is_found() -> None:
    line = without_conflict(reference(), 20, "0111", "2192")
    findings = check_line(line)
    assert any(
        f.route == "0111" and f.element == "31" and f.kind == "conflict" and "2192" in f.text
        for f in findings
    ), findings
    assert any(f.route == "2192" and f.kind == "conflict" for f in findings)


def test_flank_protection_removed_is_found() -> None:
    # 2392 runs over point 33 from track 3, the leg 0111 does not take: 0111 is protected on its
    # flank only while 2392's signal 23 is held at stop by the conflict
    line = without_conflict(reference(), 20, "0111", "2392")
    findings = check_line(line)
    assert any(
        f.route == "0111" and f.element == "33" and f.kind == "flank" and "2392" in f.text
        for f in findings
    ), findings


def test_control_table_rows_are_derived_from_the_data(tmp_path: Path) -> None:
    line = reference()
    rows = list(csv.DictReader(io.StringIO(station_csv(line, 20))))
    assert tuple(rows[0]) == COLUMNS and COLUMNS[0] == "route"
    assert [r["route"] for r in rows] == [r.name for r in line.station(20).routes]
    r0111 = next(r for r in rows if r["route"] == "0111")
    assert r0111["points"] == "31N 33N"
    assert r0111["overlap_points"] == "34N"
    assert "33: signals 02 23 at stop" in r0111["flank_protection"]
    assert r0111["approach_locking_s"] == "90"
    assert r0111["release_sections"] == "TC2053A | TC2053B | TC2055"
    r2192 = next(r for r in rows if r["route"] == "2192")
    assert r2192["interval"] == "departure into 1820"
    written = write_tables(line, tmp_path)
    assert sorted(p.name for p in written) == ["18.csv", "20.csv", "22.csv", "index.html"]
    page = index_html(line)
    assert "<script" not in page and "http" not in page.split("<body>")[1]
    assert page.count("<table>") == 3
