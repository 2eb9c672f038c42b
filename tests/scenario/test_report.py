"""Scenario reports write the data behind every plot as CSV beside its PNG: the plotted columns,
one row per cycle, and the supervision limits in their order (permitted ≤ warning ≤ SBI ≤ EBI)
wherever they were sampled — the seed 003 run whose plot once had SBI above EBI before the
90 → 60 step."""

from __future__ import annotations

import csv
from pathlib import Path

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir
from ktcs_bench.scenario.model import load_scenario
from ktcs_bench.scenario.report import LIMITS, NO_LIMIT_KMH
from ktcs_bench.scenario.runner import run

SCENARIOS = data_dir("emulators") / "scenarios"


def _rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        return list(reader.fieldnames or []), list(reader)


def test_seed003_report_csvs_hold_the_plotted_data_in_order(tmp_path: Path) -> None:
    path = SCENARIOS / "seed003_table3.yaml"
    assert main(["scenario", "run", str(path), "--out", str(tmp_path)]) == 0
    for png in ("speed_distance.png", "time_distance.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"
        assert (tmp_path / png).with_suffix(".csv").is_file(), f"no CSV beside {png}"
    trace = run(load_scenario(path)).traces["T1"]  # deterministic: the same run again

    columns, rows = _rows(tmp_path / "speed_distance.csv")
    assert columns == [
        "train", "t_s", "front_m", "speed_kmh", "safe_front_m",
        *(f"{name}_kmh" for name in LIMITS),
    ]  # fmt: skip
    assert len(rows) == len(trace.t) and {r["train"] for r in rows} == {"T1"}
    assert max(float(r["front_m"]) for r in rows) == round(max(trace.head), 4)
    sampled = [r for r in rows if r["safe_front_m"]]
    assert len(sampled) == len(trace.limits_x) > 100
    order = ("permitted_kmh", "warning_kmh", "sbi_kmh", "ebi_kmh")
    for r in sampled:
        v = [float(r[c]) for c in order]
        assert v == sorted(v), f"curves out of order at {r['safe_front_m']} m: {r}"
        assert float(r["ebi_kmh"]) <= NO_LIMIT_KMH
    # the stretch the issue named (SBI and warning were above EBI before the 90 → 60 step)
    step = [r for r in sampled if 690.0 <= float(r["safe_front_m"]) <= 770.0]
    assert len(step) >= 3, "the stretch before the 90 → 60 step was sampled"

    columns, rows = _rows(tmp_path / "time_distance.csv")
    assert columns == ["train", "t_s", "front_m", "rear_m"]
    assert len(rows) == len(trace.t)
    assert all(abs(float(r["front_m"]) - float(r["rear_m"]) - 20.0) < 1e-3 for r in rows), (
        "the rear is the front less the 20 m train"
    )


def test_marks_csv_names_the_zones_and_stop_marks_drawn(tmp_path: Path) -> None:
    path = SCENARIOS / "seed001_protection_zone.yaml"
    assert main(["scenario", "run", str(path), "--out", str(tmp_path)]) == 0
    columns, rows = _rows(tmp_path / "time_distance_marks.csv")
    assert columns[:4] == ["kind", "name", "from_m", "to_m"]
    zones = load_scenario(path).zones
    assert [(float(r["from_m"]), float(r["to_m"])) for r in rows] == [
        (z.start, z.end) for z in zones
    ]
