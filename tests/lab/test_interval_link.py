"""SPEC §6.6: adjacent IXLs are linked by a vital Type I link per interval (`iv1820`, `iv2022`),
listed in the lab file and tapped like every link. The lab file refuses a link that does not join
two IXLs of adjacent stations; each IXL is told its neighbour's role (`east` at the interval's
west end, `west` at the other); the link comes up at both ends, in a live lab (every IXL its own
process, the link a paced pty pair through its tap) and in one process (virtual wires)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench import kinds
from ktcs_bench.capture import read_capture
from ktcs_bench.chart_files.files import render
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.lab.topology import load_lab
from ktcs_bench.station.loader import load_line
from ktcs_bench.station_codes.stations import chart_spec

from .conftest import lab_file, request, start_lab, wait_until
from .test_inprocess import status, until

# what each IXL of the reference lab calls its neighbours' links: 18 and 22 are the line's ends
NEIGHBOURS = {"ixl18": ("east",), "ixl20": ("west", "east"), "ixl22": ("west",)}
IV1820 = "  - {name: iv1820,   type: type1, a: ixl18, b: ixl20, tap: true}\n"


def test_the_reference_lab_links_each_pair_of_adjacent_ixls_by_interval(tmp_path: Path) -> None:
    lab = load_lab(lab_file(tmp_path, "ivlab"))
    between = {lk.name: lk for lk in lab.links if lk.interval is not None}
    assert sorted(between) == ["iv1820", "iv2022"]
    iv = between["iv1820"]
    assert (iv.a, iv.b, iv.type, iv.tap, iv.interval) == ("ixl18", "ixl20", "type1", True, "1820")
    # the IXL at the interval's west end calls the other east; that one calls it west
    assert lab.peer_role(iv, "ixl18") == kinds.EAST
    assert lab.peer_role(iv, "ixl20") == kinds.WEST


def _bad_lab(tmp_path: Path, link: str) -> Path:
    path = lab_file(tmp_path, "badiv")
    text = path.read_text(encoding="utf-8")
    assert IV1820 in text
    path.write_text(text.replace(IV1820, link), encoding="utf-8")
    return path


BAD = [
    pytest.param("  - {name: iv1822, type: type1, a: ixl18, b: ixl22, tap: true}\n",
                 "links[9]: link iv1822: stations 18 (ixl18) and 22 (ixl22) share no interval",
                 id="not-adjacent"),
    pytest.param("  - {name: iv1820, type: type1, a: atc18, b: ixl20, tap: true}\n",
                 "links[9].a: end a of every link is an IXL", id="atc-end-a"),
    pytest.param("  - {name: iv1820, type: type1, a: ixl18, b: atc20, tap: true}\n",
                 "links[9].b: atc20 belongs to station 20, ixl18 to 18", id="atc-of-the-neighbour"),
    pytest.param("  - {name: iv1820, type: type2, a: ixl18, b: ixl20, tap: true}\n",
                 "links[9].type: link iv1820 between IXLs ixl18 and ixl20 is a vital Type I link",
                 id="type2"),
    pytest.param("  - {name: iv1820, type: type1, a: ixl18, b: ixl20, tap: false}\n",
                 "links[9].tap: link iv1820 between IXLs ixl18 and ixl20 goes through its tap",
                 id="untapped"),
    pytest.param(IV1820 + "  - {name: again, type: type1, a: ixl20, b: ixl18, tap: true}\n",
                 "links[10]: link again: ixl20 already has its west neighbour link (iv1820)",
                 id="twice"),
]  # fmt: skip


@pytest.mark.parametrize(("link", "words"), BAD)
def test_a_bad_link_between_ixls_is_refused_naming_the_file_and_the_link(
    tmp_path: Path, link: str, words: str
) -> None:
    path = _bad_lab(tmp_path, link)
    with pytest.raises(ConfigError) as caught:
        load_lab(path)
    assert str(caught.value).startswith(f"{path}: "), caught.value
    assert words in str(caught.value), caught.value
    assert "\n" not in str(caught.value)


def test_the_cli_refuses_a_lab_linking_ixls_of_stations_that_are_not_adjacent_with_exit_2(
    tmp_path: Path,
) -> None:
    path = _bad_lab(tmp_path, str(BAD[0].values[0]))
    done = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "simulate", str(path), "--for", "1",
         "--out", str(tmp_path / "run")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "iv1822" in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def test_an_ixl_told_of_a_neighbour_its_station_has_not_is_refused_with_exit_2() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "emulator", "ixl", "--station", "22",
         "--link", "east=pty"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "station 22 has no east neighbour" in done.stderr, done.stderr


def _neighbours_up(links: dict[str, Any], device: str) -> bool:
    return all(links.get(role) for role in NEIGHBOURS[device])


def test_in_one_process_the_interval_links_come_up_through_their_taps(tmp_path: Path) -> None:
    out = tmp_path / "run"
    lab = InProcessLab(lab_file(tmp_path, "ivsim"), out=out)

    async def main(lab: InProcessLab) -> dict[str, Any]:
        async def every_neighbour_up() -> bool:
            for device in NEIGHBOURS:
                if not _neighbours_up((await status(lab, device))["links"], device):
                    return False
            return True

        await until(lab, "every IXL's neighbour links up", every_neighbour_up)
        seen = {d: (await status(lab, d))["links"] for d in NEIGHBOURS}
        # the tap in the link is the lab's: a cut there is a communication error at both ends
        assert (await lab.link("iv1820", {"cmd": "cut"}))["ok"]

        async def both_ends_down() -> bool:
            return (
                not (await status(lab, "ixl18"))["links"]["east"]
                and not (await status(lab, "ixl20"))["links"]["west"]
            )

        await until(lab, "iv1820 down at ixl18 and ixl20", both_ends_down)
        assert (await status(lab, "ixl20"))["links"]["east"]  # iv2022 untouched
        assert (await lab.link("iv1820", {"cmd": "restore"}))["ok"]
        await until(lab, "every IXL's neighbour links up again", every_neighbour_up)
        return seen

    seen = lab.run(main)
    assert set(seen["ixl20"]) >= {"atc", "io", "ctc", "west", "east"}
    assert "west" not in seen["ixl18"] and "east" not in seen["ixl22"]  # the line's ends
    for name in ("iv1820", "iv2022"):
        records = read_capture(out / "captures" / f"{name}.pcapng").records
        a, b = name[2:4], name[4:6]
        assert {r.direction for r in records} == {f"ixl{a}>ixl{b}", f"ixl{b}>ixl{a}"}, name
    events = [json.loads(e) for e in (out / "events.jsonl").read_text().splitlines()]
    for device, role in (("ixl18", "east"), ("ixl20", "west")):
        said = [e["text"] for e in events if e["device"] == device and e["kind"] == "link"]
        assert said.count(f"{role} link up") == 2, said  # at the start, and after the cut
        assert f"{role} link in communication error" in said, said
    # its capture decodes with a chart each way: what ixl18 sends is its ixl_to_east, what
    # ixl20 sends its ixl_to_west (each with the sender's own half of the interval)
    shown = _monitor(tmp_path, str(out / "captures" / "iv1820.pcapng"))
    assert shown.returncode == 0, shown.stderr
    frames = shown.stdout.split("\n\n")
    infos = {f.split()[2]: f for f in frames if "ALL_INFO" in f}
    assert "PHI1820=" in infos["ixl18>ixl20"] and "TTC1861A1867=" in infos["ixl18>ixl20"]
    assert "PHI1820=" in infos["ixl20>ixl18"] and "TTC20432047=" in infos["ixl20>ixl18"]


def _monitor(
    tmp_path: Path, source: str, *args: str, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """`ktcs-bench monitor SOURCE` naming the codes of iv1820's two charts, one per sender."""
    line = load_line()
    charts = []
    for device, st, chart in (("ixl18", 18, "ixl_to_east"), ("ixl20", 20, "ixl_to_west")):
        path = tmp_path / f"st{st}_{chart}.yaml"
        path.write_text(render(chart_spec(line.view(st), chart), "the test"), encoding="utf-8")
        charts += ["--chart", f"{device}={path}"]
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "monitor", source, *charts,
         *args], capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip


def test_a_live_lab_links_its_ixl_processes_through_the_interval_taps(tmp_path: Path) -> None:
    with start_lab(tmp_path, "ivlive") as lab:
        for device in NEIGHBOURS:
            wait_until(
                f"{device}: its neighbour links up",
                lambda device=device: _neighbours_up(lab.status(device)["links"], device),
            )
        entry = lab.links["iv1820"]
        assert (entry["type"], entry["a"], entry["b"]) == ("type1", "ixl18", "ixl20")
        assert entry["a_end"].startswith("/dev/pts/") and entry["b_end"].startswith("/dev/pts/")
        assert entry["capture"].endswith("iv1820.hex")
        tap = entry["tap"]
        assert request(tap, {"cmd": "status"})["status"]["records"] > 0  # frames through its tap
        # the tap is named after the link: the monitor finds it by that name and decodes it
        shown = lab.cli("monitor", "iv1820", "--count", "2", "--timeout", "20", "--no-colour")
        assert shown.returncode == 0, shown.stderr
        assert "monitoring tap iv1820" in shown.stdout and "CRC OK" in shown.stdout, shown.stdout
        assert "ixl18>ixl20" in shown.stdout or "ixl20>ixl18" in shown.stdout
        # what it recorded from the start, codes named by the chart of each end
        env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(lab.run_dir)}
        history = _monitor(
            tmp_path, "iv1820", "--history", "--count", "30", "--timeout", "20", env=env
        )
        assert history.returncode == 0, history.stderr
        assert "TTC1861A1867=" in history.stdout and "TTC20432047=" in history.stdout
        # the link between the processes runs through the tap: cut there, down at both ends
        assert request(tap, {"cmd": "cut"})["ok"]
        wait_until(
            "iv1820 down at both ends",
            lambda: (
                not lab.status("ixl18")["links"]["east"]
                and not lab.status("ixl20")["links"]["west"]
            ),
        )
        assert request(tap, {"cmd": "restore"})["ok"]
        wait_until("iv1820 up again", lambda: lab.status("ixl18")["links"]["east"])


@pytest.mark.parametrize(
    ("given", "words"),
    [
        (["{a}", "{b}"], "--chart: one chart for every frame; SENDER=CHART for each end"),
        (["ixl18={a}", "ixl18={b}"], "--chart: two charts for the frames ixl18 sends"),
    ],
)
def test_the_monitor_takes_one_chart_per_sender_and_refuses_two(
    tmp_path: Path, given: list[str], words: str
) -> None:
    line = load_line()
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(render(chart_spec(line.view(18), "ixl_to_east"), "the test"), encoding="utf-8")
    b.write_text(render(chart_spec(line.view(20), "ixl_to_west"), "the test"), encoding="utf-8")
    charts = [arg for g in given for arg in ("--chart", g.format(a=a, b=b))]
    fig7 = str(data_dir("protocols") / "captures" / "fig7.hex")
    done = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "monitor", fig7, *charts],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2 and words in done.stderr, done.stderr
