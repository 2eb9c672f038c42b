"""Issue 15 item 1 in the real processes: trains run their timetable through stations 18, 20 and
22 -- every device its own process, the CTC's ARS setting their routes from the timetable, each
train's ATO stopping at every platform on the codes from the rails -- and both reach station 22,
each stop within ±0.5 m of its mark.

Real speed, so the line is the reference's with its intervals shortened (`short_line`: the same
stations, tables and names; 600 m of plain line between stations instead of ~5 km) and the
trains start standing at platforms: 1001 at 18, stopping at 20 and 22; 1003 at 20, ahead of it,
stopping at 22 in the loop. The whole run takes about four minutes. The full reference timetable
(both trains from the west edge, 18 -> 20 -> 22) is what `make lab` runs.
"""

from __future__ import annotations

import time
from pathlib import Path

from ktcs_bench.datafiles import data_dir
from ktcs_bench.train.endpoint import STOP_TOLERANCE

from .conftest import start_lab
from .short_line import write_short_line

TIMETABLE = """\
timetable: short
line: line.yaml
train_data:
  seed001-table1: {{length_m: 200, max_speed_kmh: 80, traction_kmh_per_s: 3,
                   service_brake_kmh_per_s: 3, emergency_brake_kmh_per_s: 4}}
trains:
  - id: "1001"
    train: seed001-table1
    direction: up
    stops:
      - {{station: 18, track: "1", stop_m: 1080, dwell_s: 0}}
      - {{station: 20, track: "1", stop_m: {st20}, dwell_s: 10}}
      - {{station: 22, track: "1", stop_m: {st22_main}, dwell_s: 10}}
  - id: "1003"
    train: seed001-table1
    direction: up
    stops:
      - {{station: 20, track: "1", stop_m: {st20}, dwell_s: 0}}
      - {{station: 22, track: "2", stop_m: {st22_loop}, dwell_s: 10}}
"""
RUN_S = 420.0  # both trains at 22 well within this (about 4 minutes measured)


def short_lab(tmp: Path, name: str) -> Path:
    """The reference lab on the short line, its two train devices on the short timetable, ARS
    on at every station."""
    folder = tmp / "short"
    shift = write_short_line(folder)
    (folder / "timetable.yaml").write_text(
        TIMETABLE.format(
            st20=6780 + shift[20], st22_main=12680 + shift[22], st22_loop=12580 + shift[22]
        )
    )
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    text = text.replace("lab: reference", f"lab: {name}").replace("port: 8020", "port: 0")
    text = text.replace("line: ../lines/reference.yaml", f"line: {folder / 'line.yaml'}")
    text = text.replace(
        "timetable: ../timetables/reference.yaml", f"timetable: {folder / 'timetable.yaml'}"
    )
    assert "\nars: {}" in text  # ARS on at every station, as in the reference lab
    path = tmp / f"{name}.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_both_trains_reach_station_22_stopping_at_every_platform_within_half_a_metre(
    tmp_path: Path,
) -> None:
    name = "ttlab"
    with start_lab(tmp_path, name, clear=False, path=short_lab(tmp_path, name)) as lab:
        end = time.monotonic() + RUN_S
        status = {}
        while time.monotonic() < end:
            status = {t: lab.status(f"train{t}") for t in ("1001", "1003")}
            if all(s["state"] == "finished" for s in status.values()):
                break
            time.sleep(1.0)
        log = lab.ctc({"cmd": "log", "last": 1000})["log"]
    for train, s in status.items():
        assert s["state"] == "finished", (train, s)
        assert s["emergency_brakes"] == 0, (train, s)
    t1001, t1003 = status["1001"], status["1003"]
    assert [a["station"] for a in t1001["arrivals"]] == ["20", "22"], t1001
    assert [a["station"] for a in t1003["arrivals"]] == ["22"], t1003
    assert [d["station"] for d in t1001["departures"]] == ["18", "20"], t1001
    assert [d["station"] for d in t1003["departures"]] == ["20"], t1003
    for s in (t1001, t1003):
        for a in s["arrivals"]:
            assert abs(a["error_m"]) <= STOP_TOLERANCE, (s["train"], a)
    # 1001 stood its 10 s at 20 before it left
    arrived = t1001["arrivals"][0]["time_s"]
    assert t1001["departures"][1]["time_s"] >= arrived + 10.0, t1001
    # the routes were ARS's: nobody else set any
    print({t: [(a["station"], a["error_m"]) for a in s["arrivals"]] for t, s in status.items()})
    assert log and {e["source"] for e in log} == {"ars"}, log
