"""Issue 15 item 1 in the real processes: trains run their timetable through stations 18, 20 and
22 -- every device its own process, the CTC's ARS setting their routes from the timetable, each
train's ATO stopping at every platform on the codes from the rails -- the up trains reach
station 22 and the down train station 18, each stop within ±0.5 m of its mark, and the down
train crosses an up train at station 20: it stands in the loop while the up train stands on the
main track (issue 23: the interval permissions change hands through the real IXL-IXL links).

Real speed, so the line is the reference's with its intervals shortened (`short_line`: the same
stations, tables and names; 600 m of plain line between stations instead of ~5 km) and the
trains start standing at platforms: 1001 at 18, stopping at 20 and 22; 1003 at 20, ahead of it,
stopping at 22 in the loop; 2001 at 22 on the main track, stopping at 20 in the loop (track 2)
and at 18 on the main track. The full reference timetable (the up trains from the west edge,
18 -> 20 -> 22, the down one from the east edge) is what `make lab` runs.
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
  - id: "2001"
    train: seed001-table1
    direction: down
    stops:
      - {{station: 22, track: "1", stop_m: {st22_down}, dwell_s: 0}}
      - {{station: 20, track: "2", stop_m: {st20_loop_down}, dwell_s: 10}}
      - {{station: 18, track: "1", stop_m: 620, dwell_s: 10}}
"""
RUN_S = 600.0  # every train at its last stop well within this


def short_lab(tmp: Path, name: str) -> tuple[Path, dict[int, float]]:
    """The reference lab on the short line, its three train devices on the short timetable, ARS
    on at every station; and how far each station moved (`write_short_line`)."""
    folder = tmp / "short"
    shift = write_short_line(folder)
    (folder / "timetable.yaml").write_text(
        TIMETABLE.format(
            st20=6780 + shift[20],
            st22_main=12680 + shift[22],
            st22_loop=12580 + shift[22],
            st22_down=12120 + shift[22],
            st20_loop_down=6120 + shift[20],
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
    return path, shift


Place = tuple[float, float]  # a train's front (m, chainage) and speed (km/h) at one look


def passed_at_20(looks: list[dict[str, Place]], station: tuple[float, float]) -> list[str]:
    """The up trains that passed 2001 (the down train) inside station 20 (`station`: its home
    signals' chainages) with one of the two standing: between two looks the up train's front
    went from below 2001's front to above it, every front at the station and one of the two
    trains at a stand at both looks. (A look: each train's front and speed, a second apart.)"""
    lo, hi = station
    out: list[str] = []
    for up in ("1001", "1003"):
        for before, after in zip(looks, looks[1:], strict=False):
            (ua, us), (ub, vs) = before[up], after[up]
            (da, ds), (db, es) = before["2001"], after["2001"]
            if not (ua < da and ub > db):
                continue
            standing = max(us, vs) < 0.1 or max(ds, es) < 0.1
            if standing and all(lo <= x <= hi for x in (ua, ub, da, db)) and up not in out:
                out.append(up)
    return out


def test_trains_both_ways_stop_within_half_a_metre_and_cross_at_station_20(
    tmp_path: Path,
) -> None:
    name = "ttlab"
    path, shift = short_lab(tmp_path, name)
    with start_lab(tmp_path, name, clear=False, path=path) as lab:
        end = time.monotonic() + RUN_S
        status = {}
        looks: list[dict[str, Place]] = []
        while time.monotonic() < end:
            status = {t: lab.status(f"train{t}") for t in ("1001", "1003", "2001")}
            looks.append({t: (s["head"], s["speed_kmh"]) for t, s in status.items()})
            if all(s["state"] == "finished" for s in status.values()):
                break
            time.sleep(1.0)
        log = lab.ctc({"cmd": "log", "last": 1000})["log"]
        ars_log = lab.ctc({"cmd": "ars", "last": 1000})["log"]
    for train, s in status.items():
        assert s["state"] == "finished", (train, s)
        assert s["emergency_brakes"] == 0, (train, s)
    t1001, t1003, t2001 = status["1001"], status["1003"], status["2001"]
    assert [a["station"] for a in t1001["arrivals"]] == ["20", "22"], t1001
    assert [a["station"] for a in t1003["arrivals"]] == ["22"], t1003
    assert [d["station"] for d in t1001["departures"]] == ["18", "20"], t1001
    assert [d["station"] for d in t1003["departures"]] == ["20"], t1003
    assert [a["station"] for a in t2001["arrivals"]] == ["20", "18"], t2001
    assert [d["station"] for d in t2001["departures"]] == ["22", "20"], t2001
    for s in (t1001, t1003, t2001):
        for a in s["arrivals"]:
            assert abs(a["error_m"]) <= STOP_TOLERANCE, (s["train"], a)
    # 1001 stood its 10 s at 20 before it left
    arrived = t1001["arrivals"][0]["time_s"]
    assert t1001["departures"][1]["time_s"] >= arrived + 10.0, t1001
    # the crossing at 20: an up train and 2001 passed each other inside station 20, one of the
    # two standing at its platform -- 2001 in the loop (track 2), the up train on the main track
    crossed = passed_at_20(looks, (6000 + shift[20], 7000 + shift[20]))
    assert crossed, looks
    assert "train 2001 arrived at station 20 track 2" in [e["text"] for e in ars_log], ars_log
    # the routes were ARS's: nobody else set any
    print({t: [(a["station"], a["error_m"]) for a in s["arrivals"]] for t, s in status.items()})
    assert log and {e["source"] for e in log} == {"ars"}, log
