"""The reference line with its two intervals shortened: the same three stations (18, 20, 22),
their layouts and interlocking tables, the same track-circuit names -- only the plain line
between them is `INTERVAL_M` long instead of about 5 km, so a train runs 18 -> 20 -> 22 in a few
minutes of real time. Written from the shipped files (stations moved along the line), for the
real-process timetable test; the code charts follow from the data, so they are the reference's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from ktcs_bench.datafiles import data_dir

INTERVAL_M = 600.0  # plain line between two stations: its six track circuits of 100 m
CHAINAGE_KEYS = ("from_m", "to_m", "position_m")


def _shifted(node: Any, by: float) -> Any:
    if isinstance(node, dict):
        return {
            k: (v + by if k in CHAINAGE_KEYS and isinstance(v, (int, float)) else _shifted(v, by))
            for k, v in node.items()
        }
    if isinstance(node, list):
        return [_shifted(v, by) for v in node]
    return node


def write_short_line(out: Path) -> dict[int, float]:
    """Write the short line into `out` (line.yaml, stations/); returns how far each station
    moved (m, negative: west)."""
    emu = data_dir("emulators")
    line = yaml.safe_load((emu / "lines" / "reference.yaml").read_text())
    intervals = {iv["name"]: iv for iv in line["intervals"]}
    shift = {18: 0.0}
    # each interval keeps its west end; the station east of it moves west by what it lost
    for name, west, east in (("1820", 18, 20), ("2022", 20, 22)):
        iv = intervals[name]
        lost = (iv["to_m"] - iv["from_m"]) - INTERVAL_M
        shift[east] = shift[west] - lost
        iv["from_m"] += shift[west]
        iv["to_m"] = iv["from_m"] + INTERVAL_M
        step = INTERVAL_M / len(iv["track_circuits"])
        tcs = {tc["name"]: tc for tc in line["track_circuits"]}
        for k, tc_name in enumerate(iv["track_circuits"]):
            tcs[tc_name]["from_m"] = iv["from_m"] + k * step
            tcs[tc_name]["to_m"] = iv["from_m"] + (k + 1) * step
    for name in ("2224",):
        intervals[name] = _shifted(intervals[name], shift[22])
    line["intervals"] = list(intervals.values())
    for tc in line["track_circuits"]:
        if tc["name"] == "TC2261":
            tc.update(_shifted({"from_m": tc["from_m"], "to_m": tc["to_m"]}, shift[22]))
    line["end_m"] += shift[22]
    line["gradients"] = [{"from_m": 0, "to_m": line["end_m"], "permille": 0}]
    line["speed_limits"] = [{"from_m": 0, "to_m": line["end_m"], "kmh": 80}]
    (out / "stations").mkdir(parents=True, exist_ok=True)
    for st in line["stations"]:
        number = st["number"]
        data = yaml.safe_load((emu / "stations" / f"st{number}.yaml").read_text())
        (out / "stations" / f"st{number}.yaml").write_text(
            yaml.safe_dump(_shifted(data, shift[number]), sort_keys=False)
        )
        st["file"] = f"stations/st{number}.yaml"
    (out / "line.yaml").write_text(yaml.safe_dump(line, sort_keys=False))
    return shift
