"""Issue 13 item 1: every kind of device killed and restarted in turn (`lab kill`, `lab restart`),
and the lab is whole again after each -- the restarted device is back at its own addresses, so
the taps, the devices and the clients that reach it need nothing new."""

from __future__ import annotations

import json
import time
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest

from .conftest import RunningLab, request, start_lab, wait_until

TRAIN = "  train1: {kind: train, train: T1, start_m: 420, length_m: 100, max_speed_kmh: 80}\n"
STATIONS = (18, 20, 22)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    with start_lab(tmp_path_factory.mktemp("restartlab"), "restartlab", TRAIN, clear=False) as lab:
        yield lab


def checks(lab: RunningLab) -> dict[str, bool]:
    """Every part of a whole lab, each True when it holds now: each station up, synced and in
    center mode at the CTC with the CTC's view equal to its IXL's state, each IXL's three links
    up, each ATC and trackside I/O on its link and on the rails, the train on the rails, and the
    console listing the train."""
    out: dict[str, bool] = {}
    stations = lab.ctc({"cmd": "status"})["status"]["stations"]
    for st in STATIONS:
        s = stations[str(st)]
        out[f"CTC: station {st} up and synced"] = (
            s["link"] == "up" and s["synced"] and s["mode"] == "center"
        )
        ixl = lab.status(f"ixl{st}")
        for role, up in ixl["links"].items():
            out[f"ixl{st}: {role} link up"] = up
        view = lab.ctc({"cmd": "show", "station": st})["state"]
        ixl_view = [ixl["ctc_state"][k] for k in sorted(ixl["ctc_state"], key=int)]
        out[f"CTC view of station {st} equals ixl{st}"] = list(view.values()) == ixl_view
        for dev in (f"atc{st}", f"io{st}"):
            d = lab.status(dev)
            out[f"{dev}: link up"], out[f"{dev}: rails up"] = d["link"], d["rails"]
    out["tc: train T1 on the rails"] = "T1" in lab.status("tc")["trains"]
    console = lab.state()["devices"]["ctc"]["console"]
    with urllib.request.urlopen(console + "api/state", timeout=5) as resp:
        out["console lists train T1"] = "T1" in json.load(resp)["trains"]
    return out


def wait_whole(lab: RunningLab, after: str, timeout: float = 90.0) -> None:
    """Every check holds again (each seen holding since `after`: on a loaded machine a paced
    Type I link may drop and come back between two looks, which is not what is tested here)."""
    end = time.monotonic() + timeout
    seen: set[str] = set()
    missing: list[str] = ["(no answer yet)"]
    while time.monotonic() < end:
        try:
            now = checks(lab)
        except (OSError, KeyError, ValueError) as exc:  # a device still coming back
            missing = [f"{type(exc).__name__}: {exc}"]
        else:
            seen |= {k for k, ok in now.items() if ok}
            missing = [k for k in now if k not in seen]
            if not missing:
                return
        time.sleep(0.2)
    raise AssertionError(f"the lab is not whole after {after}; never seen: {missing}")


def addresses(state: dict[str, Any]) -> dict[str, dict[str, Any]]:
    keys = ("control", "listen", "console")
    return {n: {k: d[k] for k in keys if k in d} for n, d in state["devices"].items()}


@pytest.mark.parametrize("device", ["tc", "ctc", "ixl20", "atc18", "io22", "train1"])
def test_a_killed_device_restarts_at_its_addresses_and_the_lab_is_whole(
    lab: RunningLab, device: str
) -> None:
    wait_whole(lab, "start")
    before = lab.state()
    old_pid = before["devices"][device]["pid"]
    assert lab.lab({"cmd": "kill", "device": device})["ok"]
    answer = lab.lab({"cmd": "restart", "device": device})
    assert answer["ok"], answer
    after = lab.state()
    assert after["devices"][device]["pid"] != old_pid
    assert addresses(after) == addresses(before)
    assert after["links"] == before["links"]
    wait_whole(lab, f"{device} was killed and restarted")
    # what an operator does next works: the CTC answers through the lab's own client
    shown = lab.cli("ctc", "--lab", "restartlab", "--json", "show", "18")
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["summary"]["link"] == "up", shown.stdout


def test_a_running_device_restarted_keeps_its_addresses(lab: RunningLab) -> None:
    wait_whole(lab, "start")
    before = lab.state()
    for device in ("ctc", "tc"):
        assert lab.lab({"cmd": "restart", "device": device})["ok"]
    assert addresses(lab.state()) == addresses(before)
    wait_whole(lab, "a restart of the running CTC and track circuits")
    # the rails came back, so station 20 reads its (empty) line again: until the new track-circuit
    # emulator has reported, losing the rails keeps every track circuit occupied (fail-safe)
    wait_until(
        "ixl20 reads its line clear from the new rails", lambda: not lab.status("ixl20")["occupied"]
    )
    ctc = lab.device("ctc")
    answer = request(
        ctc, {"cmd": "route", "action": "set", "station": 20, "entry": "01", "exit": "11"}
    )
    assert answer["ok"], answer
