"""`lab up --group station` (issue 26 part 1): a station's IXL, ATC and trackside in one process,
their Type I links still over the taps' ptys; `lab restart` and `lab kill` act on one device of a
group process, and `lab down` leaves no process behind. Real processes, real ptys."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from ktcs_bench.runtime import process_alive, process_started

from .conftest import RunningLab, request, start_lab, wait_until
from .test_lab import route, summary

STATIONS = (18, 20, 22)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    tmp = tmp_path_factory.mktemp("grouplab")
    with start_lab(tmp, "grouplab", up_args=("--group", "station")) as lab:
        yield lab


def synced(lab: RunningLab, st: int) -> bool:
    s = lab.ctc({"cmd": "status"})["status"]["stations"][str(st)]
    return bool(s["link"] == "up" and s["synced"] and s["mode"] == "center")


def answers(address: str) -> bool:
    try:
        return bool(request(address, {"cmd": "status"}, timeout=5)["ok"])
    except OSError:
        return False


def test_a_station_s_devices_share_one_process_and_status_names_it(lab: RunningLab) -> None:
    devices = lab.state()["devices"]
    for st in STATIONS:
        pids = {devices[f"{k}{st}"]["pid"] for k in ("ixl", "atc", "io")}
        assert len(pids) == 1, devices
        assert {devices[f"{k}{st}"]["process"] for k in ("ixl", "atc", "io")} == {f"st{st}"}
    others = {devices[n]["pid"] for n in ("ctc", "tc")}
    assert len(others) == 2 and not others & {devices["ixl20"]["pid"]}
    status = lab.lab({"cmd": "status"})["status"]["devices"]
    assert status["atc18"]["process"] == {"pid": devices["atc18"]["pid"], "name": "st18"}
    shown = lab.cli("lab", "status", "grouplab")
    assert shown.returncode == 0, shown.stderr
    assert f"st20 (pid {devices['ixl20']['pid']}): " in shown.stdout, shown.stdout
    # every link of the grouped devices is up, over the taps' ptys as in a lab of processes
    for st in STATIONS:
        assert lab.status(f"ixl{st}")["links"]["atc"] and lab.status(f"io{st}")["link"]
        assert lab.links[f"st{st}-atc"]["a_end"].startswith("/dev/pts/")


def test_a_route_set_through_the_ctc_clears_its_signal(lab: RunningLab) -> None:
    with route(lab, 20, "01", "11"):
        assert summary(lab, 20)["signals"]["01"] != "R"


def test_restarting_an_ixl_in_a_group_brings_it_back_and_its_station_resyncs(
    lab: RunningLab,
) -> None:
    before = lab.state()["devices"]
    assert lab.lab({"cmd": "restart", "device": "ixl20"})["ok"]
    after = lab.state()["devices"]
    assert after["ixl20"]["control"] == before["ixl20"]["control"]
    assert after["ixl20"]["pid"] == before["ixl20"]["pid"]  # its group process ran on
    wait_until("station 20 resyncs at the CTC", lambda: synced(lab, 20), timeout=60)
    wait_until("ixl20's links all up", lambda: all(lab.status("ixl20")["links"].values()))


def test_killing_an_atc_leaves_the_rest_of_its_group_running(lab: RunningLab) -> None:
    atc = lab.device("atc18")
    assert lab.lab({"cmd": "kill", "device": "atc18"})["ok"]
    assert not answers(atc)
    status = lab.lab({"cmd": "status"})["status"]["devices"]
    assert status["atc18"]["alive"] is False
    assert status["ixl18"]["alive"] and status["io18"]["alive"]
    assert lab.status("io18")["link"]
    wait_until("ixl18 sees its ATC link drop", lambda: not lab.status("ixl18")["links"]["atc"])
    assert lab.lab({"cmd": "restart", "device": "atc18"})["ok"]
    assert lab.device("atc18") == atc
    wait_until("ixl18's ATC link back", lambda: lab.status("ixl18")["links"]["atc"], timeout=60)
    wait_until("station 18 synced", lambda: synced(lab, 18), timeout=60)


def test_a_grouped_device_stopped_by_its_own_command_ends_alone(lab: RunningLab) -> None:
    io = lab.device("io22")
    assert request(io, {"cmd": "stop"})["ok"]
    wait_until("io22's control port closed", lambda: not answers(io))
    wait_until(
        "the lab sees io22 ended and ixl22 running",
        lambda: (
            (d := lab.lab({"cmd": "status"})["status"]["devices"])
            and not d["io22"]["alive"]
            and d["ixl22"]["alive"]
        ),
    )
    assert lab.lab({"cmd": "restart", "device": "io22"})["ok"]
    wait_until(
        "ixl22's trackside link back", lambda: lab.status("ixl22")["links"]["io"], timeout=60
    )


def test_a_station_process_killed_is_three_crashes_each_restarted_alone(lab: RunningLab) -> None:
    pid = lab.state()["devices"]["ixl22"]["pid"]
    os.killpg(pid, signal.SIGKILL)
    wait_until(
        "the lab sees station 22's three devices dead",
        lambda: (
            not any(
                d["alive"]
                for n, d in lab.lab({"cmd": "status"})["status"]["devices"].items()
                if n.endswith("22")
            )
        ),
    )
    for device in ("io22", "atc22", "ixl22"):
        assert lab.lab({"cmd": "restart", "device": device})["ok"]
    devices = lab.state()["devices"]
    assert len({devices[f"{k}22"]["pid"] for k in ("ixl", "atc", "io")} - {pid}) == 1
    wait_until("station 22 resyncs at the CTC", lambda: synced(lab, 22), timeout=60)
    wait_until("ixl22's links all up", lambda: all(lab.status("ixl22")["links"].values()))


def descendants(root: int) -> set[tuple[int, int | None]]:
    """Every live process under `root`, with its start time (from /proc)."""
    parent: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rpartition(")")[2].split()
            except OSError:
                continue
            parent[int(entry.name)] = int(fields[1])
    out, todo = set(), [root]
    while todo:
        at = todo.pop()
        kids = [c for c, p in parent.items() if p == at]
        out |= {(k, process_started(k)) for k in kids}
        todo += kids
    return out


def test_lab_down_leaves_no_process_behind(lab: RunningLab) -> None:
    devices = lab.state()["devices"]
    procs = {(d["pid"], d["started"]) for d in devices.values()}
    assert len(procs) == 2 + len(STATIONS)  # ctc, tc and one process per station
    procs |= descendants(lab.proc.pid)  # and the template the station processes are forked from
    assert len(procs) == 3 + len(STATIONS), procs
    down = lab.cli("lab", "down", "grouplab")
    assert down.returncode == 0, down.stderr
    assert lab.proc.wait(30) == 0
    wait_until(
        "every process of the lab gone",
        lambda: not [p for p, started in procs if process_alive(p, started)],
    )
