"""ARS wired into the CTC device, in one process: the real `CtcDevice` (its Type II server on TCP
127.0.0.1, its control-port commands, its desk) and the three reference stations' real
interlockings as Type II clients (`console.demo.RigIxl`). A train is the track circuits the test
occupies at an IXL; ARS must see it through the indications, ask through the desk, and stop asking
where the operator switched it off. Also: the lab file's `ars:` section."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.console.demo import RigIxl
from ktcs_bench.datafiles import data_dir
from ktcs_bench.emulator.ctc import CtcDevice
from ktcs_bench.errors import ConfigError
from ktcs_bench.lab.topology import load_lab

from .ars_rig import LINE, TIMETABLE

STATIONS = [18, 20, 22]


async def until(what: str, predicate: Callable[[], Any], timeout: float = 10.0) -> Any:
    """Wait for `predicate` (re-checked as the loop runs: the links' events, ARS's timers)."""
    end = asyncio.get_running_loop().time() + timeout
    while not (value := predicate()):
        if asyncio.get_running_loop().time() > end:
            raise AssertionError(f"timed out waiting for: {what}")
        await asyncio.sleep(0.01)
    return value


def run_with_ctc(
    test: Callable[[CtcDevice, dict[int, RigIxl]], Awaitable[None]], on: tuple[int, ...]
) -> None:
    async def main() -> None:
        ctc = CtcDevice("ctc", LINE, STATIONS, ("127.0.0.1", 0), timetable=TIMETABLE, ars_on=on)
        await ctc.start()
        rigs = {st: RigIxl(LINE, st) for st in STATIONS}
        try:
            for rig in rigs.values():
                rig.start("127.0.0.1", ctc.server.port)
            await until(
                "every station synced at the CTC",
                lambda: all(t.known for t in ctc.model.tables.stations.values()),
            )
            await test(ctc, rigs)
        finally:
            for rig in rigs.values():
                await rig.close()
            await ctc.close()

    asyncio.run(main())


def train(ctc: CtcDevice, number: str) -> dict[str, Any]:
    status = ctc.status()["ars"]
    return next(t for t in status["trains"] if t["train"] == number)  # type: ignore[no-any-return]


def test_ars_in_the_ctc_sets_a_route_through_the_desk_only_where_it_is_on() -> None:
    async def test(ctc: CtcDevice, rigs: dict[int, RigIxl]) -> None:
        answer = await ctc.command({"cmd": "ars", "station": 18, "on": False})
        assert answer["ok"] and answer["ars"]["stations"] == {"18": False, "20": True, "22": True}
        rigs[18].occupy("TC1851")  # train 1001 on the approach to station 18's home signal 01
        await until(
            "train 1001 waiting: ARS is off at 18",
            lambda: train(ctc, "1001")["waiting"] == "ARS off at station 18",
        )
        assert rigs[18].rig.ctc["RSI180111"] == 0  # nothing asked for
        assert not [e for e in ctc.desk.log.entries if e["source"] == "ars"]
        events = [e["text"] for e in ctc.events if e["kind"] == "ars"]
        assert "train 1001 waits for route 01-11 at station 18: ARS off at station 18" in events

        answer = await ctc.command({"cmd": "ars", "station": "18", "on": True})
        assert answer["ok"] and answer["ars"]["stations"]["18"] is True
        await until("route 01-11 set at station 18", lambda: rigs[18].rig.ctc["RSI180111"] == 1)
        (sent,) = [e for e in ctc.desk.log.entries if e["source"] == "ars"]
        assert sent["command"] == "route set 18 01 11"
        await until("its result logged", lambda: sent.get("result") == "accepted")
        await until(
            "its signal clear at the CTC", lambda: ctc.model.summary(18)["signals"]["01"] != "R"
        )
        answer = await ctc.command({"cmd": "ars", "last": 50})
        texts = [e["text"] for e in answer["log"]]
        assert "train 1001: requests route 01-11 at station 18" in texts
        assert "train 1001: route 01-11 at station 18 accepted" in texts

    run_with_ctc(test, on=(18, 20, 22))


def test_ars_switched_off_everywhere_asks_for_nothing_and_a_bad_switch_is_refused() -> None:
    async def test(ctc: CtcDevice, rigs: dict[int, RigIxl]) -> None:
        assert ctc.ars_state() == {"18": False, "20": False, "22": False}
        assert (await ctc.command({"cmd": "ars", "on": True}))["ars"]["stations"] == {
            "18": True, "20": True, "22": True,
        }  # fmt: skip
        assert (await ctc.command({"cmd": "ars", "on": False}))["ok"]
        for bad, error in (
            ({"on": "yes"}, "on must be true or false"),
            ({"on": True, "station": 99}, "station 99 is not in this lab"),
        ):
            answer = await ctc.command({"cmd": "ars", **bad})
            assert not answer["ok"] and error in answer["error"], answer
        assert ctc.ars_state() == {"18": False, "20": False, "22": False}
        rigs[18].occupy("TC1851")
        await until(
            "train 1001 waiting: ARS is off",
            lambda: train(ctc, "1001")["waiting"] == "ARS off at station 18",
        )
        assert rigs[18].rig.ctc["RSI180111"] == 0

    run_with_ctc(test, on=())


def test_a_ctc_without_a_timetable_says_ars_needs_one() -> None:
    ctc = CtcDevice("ctc", LINE, STATIONS, ("127.0.0.1", 0))
    answer = asyncio.run(ctc.command({"cmd": "ars", "on": True}))
    assert not answer["ok"] and "ARS needs `ars:` in the lab file" in answer["error"]
    assert ctc.status()["ars"] is None and ctc.ars_state() is None


def lab_with(tmp_path: Path, ars: str, timetable: bool = True) -> Path:
    """The shipped reference lab with `ars` (YAML text) for its own `ars:` section, its timetable
    only if `timetable`."""
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    text = "".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("ars:"))
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("line: ../lines/reference.yaml", f"line: {line}")
    wanted = f"timetable: {TIMETABLE_FILE}" if timetable else ""
    text = text.replace("timetable: ../timetables/reference.yaml", wanted) + ars
    path = tmp_path / "lab.yaml"
    path.write_text(text, encoding="utf-8")
    return path


TIMETABLE_FILE = (data_dir("emulators") / "timetables" / "reference.yaml").resolve()


def test_the_lab_files_ars_section_runs_the_labs_timetable_on_where_it_starts_on(
    tmp_path: Path,
) -> None:
    shipped = load_lab().ars  # the shipped reference lab runs its timetable with ARS on
    assert shipped is not None and shipped.start_on == (18, 20, 22)
    lab = load_lab(lab_with(tmp_path, "ars: {}\n"))
    assert lab.ars is not None and lab.ars.start_on == (18, 20, 22)  # on everywhere unless told
    lab = load_lab(lab_with(tmp_path, "ars: {start_on: [22, 18]}\n"))
    assert lab.ars is not None and lab.ars.start_on == (18, 22)
    assert load_lab(lab_with(tmp_path, "")).ars is None


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("ars: 5", "ars: must be a mapping {start_on: [STATION, ...] | all}"),
        ("ars: {}", "ars: ARS sets the routes of the lab's timetable: give it (timetable: FILE)"),
        ("ars: {start_on: [18, 24]}",
         "ars.start_on[1]: must be a station of the lab [18, 20, 22], not 24"),
        ("ars: {start_on: some}", "ars.start_on: a list of the lab's stations, or all; not 'some'"),
        ("ars: {stations: [18]}", "ars.stations: unknown key (ars takes start_on)"),
        ("ars: {on: [18]}",
         "ars.true: YAML reads this key as a boolean: the stations where ARS starts on are"),
    ],
    ids=["scalar", "no-timetable", "station", "start-on-word", "unknown-key", "on-key"],
)  # fmt: skip
def test_a_bad_ars_section_is_one_config_error_naming_the_lab_file_and_key(
    tmp_path: Path, section: str, message: str
) -> None:
    path = lab_with(tmp_path, section + "\n", timetable="timetable" not in message)
    with pytest.raises(ConfigError) as caught:
        load_lab(path)
    assert str(caught.value).startswith(f"{path}: "), str(caught.value)
    assert message in str(caught.value), str(caught.value)
