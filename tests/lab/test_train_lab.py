"""Issue 6 item 7: the train endpoint as its own process in `lab up` -- a route set at the CTC
lets an ATO-driven train run through a station and release the routes behind it."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from .conftest import RunningLab, request, start_lab, wait_until

TRAIN = "  train1: {kind: train, train: T1, start_m: 420, length_m: 100, max_speed_kmh: 80}\n"


@pytest.fixture(scope="module")
def train_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    with start_lab(tmp_path_factory.mktemp("trainlab"), "trainlab", TRAIN, clear=False) as lab:
        yield lab


def routes(lab: RunningLab) -> list[str]:
    return lab.ctc({"cmd": "show", "station": 18})["summary"]["routes"]  # type: ignore[no-any-return]


def test_ato_train_runs_through_station_18_and_releases_the_routes(train_lab: RunningLab) -> None:
    lab = train_lab
    first = wait_until("the train reports its position and occupies its track circuit",
                       lambda: (s := lab.status("train1"))["code_tc"] and s)  # fmt: skip
    assert first["code_tc"] == "TC1851"
    # with home signal 01 at stop the code of TC1851 ends at the signal: the train may close up
    # to it (how far it got by the first status depends on the machine), never beyond
    standing = wait_until("the train stands in front of home signal 01, at stop",
                          lambda: (s := lab.status("train1"))["speed_kmh"] == 0.0 and s)  # fmt: skip
    assert standing["code_tc"] == "TC1851", "with the home signal at stop the train must stand"
    wait_until("the CTC shows the train's track circuit occupied (rails -> ATC -> IXL -> CTC)",
               lambda: "TC1851" in lab.ctc({"cmd": "show", "station": 18})["summary"]["occupied"])  # fmt: skip
    for entry, exit_ in (("01", "11"), ("11", "91")):
        answer = lab.ctc(
            {"cmd": "route", "action": "set", "station": 18, "entry": entry, "exit": exit_}
        )
        assert answer["ok"], answer
    wait_until("the train moves off under ATO", lambda: lab.status("train1")["speed_kmh"] > 5)
    wait_until("home signal 01 back to stop once the train entered",
               lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["signals"]["01"] == "R",
               timeout=60)  # fmt: skip
    wait_until(
        "route 01-11 released behind the train", lambda: "0111" not in routes(lab), timeout=120
    )
    wait_until(
        "route 11-91 released behind the train", lambda: "1191" not in routes(lab), timeout=120
    )
    status = lab.status("train1")
    assert status["tail"] > 1100, status  # it really ran through the station
    assert status["status"] in ("normal", "indication", "overspeed", "warning"), status


def test_console_lists_the_lab_train_and_its_curves_come_from_the_train_process(
    train_lab: RunningLab,
) -> None:
    import json
    import urllib.request

    lab = train_lab
    answer = lab.lab({"cmd": "status"})
    assert answer["ok"]
    sd = request(lab.device("train1"), {"cmd": "speed_distance"})
    assert sd["ok"] and sd["data"]["train"] == "T1"
    curves = sd["data"]["curves"]
    assert set(curves) >= {"mrsp", "ebi", "sbi", "permitted"} and len(sd["data"]["x"]) > 10
    url = lab.state()["devices"]["ctc"]["console"]
    with urllib.request.urlopen(url + "api/state", timeout=10) as resp:
        state = json.load(resp)
    assert "T1" in state["trains"], state.get("trains")
