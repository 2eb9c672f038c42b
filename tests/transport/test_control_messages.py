"""The control plane's messages (`ktcs_bench.messages`): every command a device's control port
takes round-trips through its JSON, and a bad one sent to a real control port (a device on a real
TCP socket, its token presented) gets one clear `{"ok": false, "error": ...}` answer -- an unknown
cmd, a key missing or misspelt, a value of the wrong type -- while a good one is carried out."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from typing import Any

import pytest

from ktcs_bench import messages as m
from ktcs_bench.ctc.log import command_words, parse_words
from ktcs_bench.emulator.ctc import CtcDevice
from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.trackcircuit import TrackCircuitDevice
from ktcs_bench.station.loader import load_line
from ktcs_bench.transport import jsonlines

LINE = load_line()
TOKEN = "t" * 32

EXAMPLES: list[m.Message] = [
    m.Status(), m.Events(), m.Events(last=3), m.Stop(),
    m.Route(station=18, entry="S1", exit="S11"), m.Route(action="cancel", station="18", entry="01"),
    m.Point(station=20, point="31", position="reverse"), m.Signal(station=18, signal="01"),
    m.Signal(station=18, signal="01", action="release"), m.Mode(station=20, mode="local"),
    m.Control(station=18, code="CMQ18", value=0), m.Show(station=22), m.Show(), m.Log(last=5),
    m.Ars(), m.Ars(station=18, on=False, last=7), m.AddTrain(train="1001", control="h:1"),
    m.TimedRoute(station=18, entry="S1", exit="S11", timeout=5.5),
    m.LocalControl(code="CMQ18"), m.LocalControl(code=7, value=0), m.Local(action="grant"),
    m.FailPoint(point="31", kind="jammed"), m.FailLamp(signal="01", aspect="G"),
    m.FailTrackCircuit(tc="TC1851", kind="failed_clear"), m.ClearFaults(),
    m.Fail(tc="TC1851", kind="dead"), m.Clear(), m.Clear(tc="TC1851"),
    m.Place(train="G1", head=1300.0, tail=1260.5, track="2"), m.Remove(train="G1"),
    m.ReleaseEb(), m.Hold(), m.Dispatch(), m.Dispatch(now=True), m.RunTo(at=5200.0),
    m.SpeedDistance(), m.AskDirection(station=20, interval="1820"),
]  # fmt: skip
UNIONS = {"ctc": m.CTC, "ixl": m.IXL, "trackside": m.TRACKSIDE, "tc": m.TRACK_CIRCUITS,
          "train": m.TRAIN, "device": m.DEVICE}  # fmt: skip


def every_message_class() -> set[type[m.Message]]:
    found: set[type[m.Message]] = set()
    todo = [m.Message]
    while todo:
        for sub in todo.pop().__subclasses__():
            found.add(sub)
            todo.append(sub)
    return found


def test_every_message_is_in_a_union_and_round_trips_through_its_json() -> None:
    assert {type(e) for e in EXAMPLES} == every_message_class()  # a new message: add it here
    in_unions = {cls for union in UNIONS.values() for cls in m.members(union)}
    assert in_unions == every_message_class()
    for example in EXAMPLES:
        unions = [u for u in UNIONS.values() if type(example) in m.members(u)]
        for union in unions:
            line = json.dumps(m.encode(example))  # as a client puts it on the wire
            back = m.decode(json.loads(line), union)
            assert back == example and type(back) is type(example)
            assert json.loads(line)["cmd"] == example.cmd()


def test_the_ctc_console_words_are_the_messages_the_port_takes() -> None:
    for words in ("route set 18 S1 S11", "route cancel 18 01 11", "point reverse 20 31",
                  "signal release 18 01", "mode local 20", "control 18 CMQ18 0",
                  "direction 20 1820"):  # fmt: skip
        message = parse_words(words.split())
        assert m.decode(m.encode(message), m.CTC) == message
        assert command_words(message) == command_words(m.encode(message))
    assert parse_words(["ars", "off", "20"]) == m.Ars(station=20, on=False)
    assert m.encode(parse_words(["route", "set", "18", "S1", "S11"])) == {
        "cmd": "route", "station": 18, "entry": "S1", "exit": "S11",
    }  # fmt: skip


def on_a_real_port(
    make: Callable[[], Device], test: Callable[[Callable[[dict[str, Any]], Any]], Awaitable[None]]
) -> None:
    async def main() -> None:
        device = make()
        tasks = await device.launch(TOKEN)
        host, _, port = device.ready_info["control"].rpartition(":")

        async def ask(obj: dict[str, Any]) -> Any:
            return await jsonlines.request(host, int(port), obj, token=TOKEN)

        try:
            await test(ask)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await device.close()

    asyncio.run(main())


@pytest.mark.parametrize(
    ("sent", "error"),
    [
        ({"cmd": "fly"}, "unknown command 'fly'"),
        ({"station": 18}, 'a command needs "cmd"'),
        ({"cmd": 7}, "unknown command 7"),
        ({"cmd": "route", "station": 18, "entyr": "S1", "exit": "S11"},
         "route: unknown key 'entyr'"),
        ({"cmd": "route", "station": 18, "exit": "S11"}, "route command without 'entry'"),
        ({"cmd": "route", "station": 18, "entry": 1, "exit": "S11"},
         "route: entry must be text, not 1"),
        ({"cmd": "route", "action": "sett", "station": 18, "entry": "S1", "exit": "S11"},
         "route: action must be 'set' or 'cancel', not 'sett'"),
        ({"cmd": "log", "last": "5"}, "log: last must be an integer, not '5'"),
        ({"cmd": "ars", "on": "yes"}, "ars: on must be true or false, not 'yes'"),
        ({"cmd": "show", "stattion": 18}, "show: unknown key 'stattion'"),
    ],
)  # fmt: skip
def test_a_bad_command_on_the_ctc_control_port_gets_one_clear_error(
    sent: dict[str, Any], error: str
) -> None:
    async def test(ask: Callable[[dict[str, Any]], Any]) -> None:
        answer = await ask(sent)
        assert answer["ok"] is False and set(answer) == {"ok", "error"}
        assert answer["error"].startswith(error), answer
        assert (await ask({"cmd": "log"}))["log"] == []  # nothing was carried out
        shown = await ask({"cmd": "show", "station": 18})  # and the port still answers
        assert shown["ok"] and "summary" in shown

    on_a_real_port(lambda: CtcDevice("ctc", LINE, [18, 20, 22], ("127.0.0.1", 0)), test)


def test_the_track_circuits_take_a_good_command_and_refuse_a_misspelt_one() -> None:
    async def test(ask: Callable[[dict[str, Any]], Any]) -> None:
        bad = await ask({"cmd": "fail", "tc": "TC1851", "knd": "dead"})
        assert bad == {"ok": False, "error": bad["error"]}
        assert bad["error"].startswith("fail: unknown key 'knd' (its keys: tc, kind)")
        wrong = await ask({"cmd": "place", "train": "G1", "head": "1300", "tail": 1260})
        assert wrong["error"] == "place: head must be a number, not '1300'"
        status = (await ask({"cmd": "status"}))["status"]
        assert status["faults"] == {} and status["trains"] == {}
        assert (await ask({"cmd": "fail", "tc": "TC1851", "kind": "no_code"})) == {"ok": True}
        assert (await ask({"cmd": "place", "train": "G1", "head": 1300, "tail": 1260})) == {
            "ok": True
        }
        status = (await ask({"cmd": "status"}))["status"]
        assert status["faults"] == {"TC1851": "no_code"} and status["trains"] == {
            "G1": [1300.0, 1260.0, "1"]
        }

    on_a_real_port(lambda: TrackCircuitDevice("tc", LINE, ("127.0.0.1", 0)), test)
