"""A generated line runs for real: `lab up` on the lab file `line generate` wrote starts every
device as its own process, and every station comes up synced at the CTC in center mode with its
Type I and Type II links up; `lab simulate` on it runs the timetable's trains, their routes set by
the CTC's ARS, from platform to platform to the end of the line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ktcs_bench.lab.generate import write_line
from ktcs_bench.station import load_line
from tests.lab.conftest import start_lab, wait_until


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip


def test_generated_three_station_lab_comes_up_in_center_mode_with_links_up(
    tmp_path: Path,
) -> None:
    write_line(3, tmp_path / "line3")
    line = load_line(tmp_path / "line3" / "line.yaml")
    # not an empty line: the timetable's trains stand at station 12 from the start
    with start_lab(tmp_path, "line3", path=tmp_path / "line3" / "lab.yaml", clear=False) as lab:

        def every_station_up() -> bool:
            stations = lab.ctc({"cmd": "status"})["status"]["stations"]
            return sorted(stations) == ["12", "14", "16"] and all(
                s["link"] == "up"
                and s["synced"]
                and s["mode"] == "center"
                # its ATC reports: not the fail-safe picture of every circuit occupied (the
                # timetable's trains stand at station 12)
                and len(s["occupied"]) < len(line.view(int(st)).track_circuits)
                for st, s in stations.items()
            )

        wait_until("stations 12, 14, 16 synced at the CTC in center mode", every_station_up)
        # each IXL's links: its station's, and one to each neighbouring IXL (12 is the line's
        # west end: only an east neighbour; 16 the east end)
        neighbours = {12: {"east": True}, 14: {"west": True, "east": True}, 16: {"west": True}}
        for st in (12, 14, 16):
            ixl = wait_until(
                f"ixl{st}: center mode, ATC, trackside, CTC and neighbouring IXLs' links up",
                lambda st=st: (
                    (s := lab.status(f"ixl{st}"))["mode"] == "center"
                    and s["links"] == {"atc": True, "io": True, "ctc": True, **neighbours[st]}
                    and s
                ),
            )
            assert ixl["station"] == st
            assert lab.status(f"atc{st}")["kind"] == "atc"
            assert lab.status(f"io{st}")["kind"] == "trackside"
        links = {f"st{st}-{end}" for st in (12, 14, 16) for end in ("ctc", "atc", "io")}
        links |= {"iv1214", "iv1416"}  # the neighbouring IXLs' links
        assert links == set(lab.links) - {n for n in lab.links if " " in n}  # not "ctc listens"
        assert all("tap" in lab.links[name] for name in links)  # every link through its tap


def test_a_simulated_generated_line_runs_its_trains_and_stops_them_at_the_platforms(
    tmp_path: Path,
) -> None:
    folder, out = tmp_path / "line3", tmp_path / "run"
    made = _cli("line", "generate", "--stations", "3", "--out", str(folder))
    assert made.returncode == 0, made.stderr
    run_ = _cli("lab", "simulate", str(folder / "lab.yaml"), "--for", "1000", "--out", str(out))
    assert run_.returncode == 0, run_.stderr
    trains = json.loads((out / "summary.json").read_text())["trains"]
    assert sorted(trains) == ["trainT1", "trainT2"]
    timetable = {"trainT1": {"14": 6780.0, "16": 12480.0}, "trainT2": {"14": 6880.0, "16": 12380.0}}
    for name, stops in timetable.items():
        t = trains[name]
        # it left its first stop and the next, and stood at each later platform on its mark
        assert [d["station"] for d in t["departures"]] == ["12", "14"], (name, t)
        assert [(a["station"], a["stop_m"]) for a in t["arrivals"]] == list(stops.items()), t
        assert all(abs(a["error_m"]) <= 0.5 for a in t["arrivals"]), (name, t["arrivals"])
        assert t["state"] == "finished" and t["speed_kmh"] == 0 and t["emergency_brakes"] == 0, t
    events = [json.loads(e) for e in (out / "events.jsonl").read_text().splitlines()]
    ars = [e["text"] for e in events if e["device"] == "ctc" and e["kind"] == "ars"]
    for train in ("T1", "T2"):  # the CTC's ARS set their routes and saw them to their terminus
        assert f"train {train}: requests route 01-1{train[1]} at station 14" in ars, ars
        assert any(f"train {train} terminates at station 16" in a for a in ars), ars
