"""Automatic route setting in the real lab: `lab up` of the reference lab without its train
devices and with `ars:` (every device its own process), a train placed on the approach to station 18 through the track-circuit emulator,
operated with the real `ktcs-bench ctc ars` command and the console in headless Chromium."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import expect

from ktcs_bench.datafiles import data_dir

from .conftest import RunningLab, lab_file, request, start_lab, wait_until

LAB = "arslab"
TIMETABLE = (data_dir("emulators") / "timetables" / "reference.yaml").resolve()


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    tmp = tmp_path_factory.mktemp(LAB)
    path = lab_file(tmp, LAB)
    ars = f"\ntimetable: {TIMETABLE}\nars: {{}}\n"  # the timetable, no train runs it; ARS on
    path.write_text(path.read_text(encoding="utf-8") + ars)
    with start_lab(tmp, LAB, path=path) as running:
        yield running


def ctc(lab: RunningLab, *words: str) -> str:
    result = lab.cli("ctc", "--lab", LAB, "--no-colour", *words)
    assert result.returncode == 0, (words, result.stdout, result.stderr)
    return result.stdout


def waiting(lab: RunningLab, train: str) -> str | None:
    trains = lab.ctc({"cmd": "ars"})["ars"]["trains"]
    return next((t["waiting"] for t in trains if t["train"] == train), None)


def routes(lab: RunningLab, station: int) -> list[str]:
    return lab.ctc({"cmd": "show", "station": station})["summary"]["routes"]  # type: ignore[no-any-return]


def test_ars_sets_the_route_of_a_train_on_the_approach_only_where_it_is_switched_on(
    lab: RunningLab,
) -> None:
    assert "station 18 off, 20 on, 22 on" in ctc(lab, "ars", "off", "18")
    # train 1001 of the timetable comes onto the line before station 18's home signal 01
    place = {"cmd": "place", "train": "T1", "head": 450.0, "tail": 250.0, "track": "1"}
    assert request(lab.device("tc"), place)["ok"]
    wait_until(
        "train 1001 waits at 18 because ARS is off there",
        lambda: waiting(lab, "1001") == "ARS off at station 18",
    )
    assert "0111" not in routes(lab, 18)  # the train is seen, and nothing was asked for
    assert "waits: ARS off at station 18" in ctc(lab, "ars")

    assert "station 18 on, 20 on, 22 on" in ctc(lab, "ars", "on", "18")
    wait_until("ARS sets route 01-11 at station 18", lambda: "0111" in routes(lab, 18))
    wait_until(
        "signal 01 of station 18 clears",
        lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["signals"]["01"] != "R",
    )
    assert "route set 18 01 11 (by ARS) -> accepted" in ctc(lab, "log")


def test_the_console_shows_ars_per_station_and_switches_it(
    browser_context: Any, lab: RunningLab
) -> None:
    page = browser_context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        page.goto(lab.state()["devices"]["ctc"]["console"])
        page.wait_for_selector("#conn.up")
        button = page.locator("#card-22 button.ars")
        expect(button).to_have_text("ARS on", timeout=20_000)
        button.click()
        expect(page.locator("#result")).to_have_text("station 22: ARS off", timeout=20_000)
        expect(button).to_have_text("ARS off")
        assert lab.ctc({"cmd": "ars"})["ars"]["stations"]["22"] is False  # the CTC's own state
        ctc(lab, "ars", "on", "22")  # switched elsewhere: the page follows
        expect(button).to_have_text("ARS on", timeout=20_000)
    finally:
        page.close()
    assert not errors, f"JavaScript errors on the page: {errors}"
