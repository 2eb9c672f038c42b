"""The operator's desk over real TCP on 127.0.0.1: a CTC server, station 18's real interlocking
(`console.demo.RigIxl`) as its Type II client, and the one path every operator command takes --
from `ktcs-bench ctc` (the CTC's control port) or a click on the console -- into one command log."""

from __future__ import annotations

import asyncio

from ktcs_bench.console.demo import RigIxl
from ktcs_bench.console.server import ConsoleServer
from ktcs_bench.ctc.desk import Desk
from ktcs_bench.ctc.model import CtcModel
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.station.loader import load_line
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.type2 import events as ev

LINE = load_line()


def run(coro: object) -> None:
    async def main() -> None:
        await asyncio.wait_for(coro, 30.0)  # type: ignore[arg-type]

    asyncio.run(main())


def test_commands_from_the_port_and_the_console_go_one_way_into_one_log() -> None:
    async def main() -> None:
        model = CtcModel(LINE)
        answers: list[ev.ControlAnswered] = []

        def seen(station: int | None, e: ev.SessionEvent) -> None:
            if isinstance(e, ev.ControlAnswered):
                answers.append(e)

        async with CtcServer(sorted(LINE.stations), model.tables, on_event=seen) as ctc:
            desk = Desk(model, ctc, clock=asyncio.get_running_loop().time, timeout=5.0)
            rig = RigIxl(LINE, 18, mode=Mode.CENTER)
            rig.start("127.0.0.1", ctc.port)
            try:
                await ctc.wait_until(lambda: model.tables.stations[18].known)
                route = {"cmd": "route", "station": 18, "entry": "S1", "exit": "S11"}
                done = await desk.operate({**route, "action": "set"})
                assert done.accepted and done.result == "accepted"
                assert rig.rig.ctc["RSI180111"] == 1  # really set in the interlocking
                await ctc.wait_until(lambda: model.summary(18)["routes"] == ["0111"])
                # a conflicting route goes out and comes back rejected, with the reason's name
                clash = await desk.operate({**route, "exit": "12", "action": "set"})
                assert clash.answered and not clash.accepted and clash.reason == 2
                assert clash.result == "rejected: route conflicts"
                # what the model refuses never goes out
                sent = len(answers)
                nothing = await desk.operate({**route, "exit": "02", "action": "set"})
                assert nothing.action is None and not nothing.answered
                assert nothing.why == "station 18: no route from signal 01 to 02"
                # a station whose IXL is not connected: no answer, and why
                away = await desk.operate({"cmd": "mode", "station": 20, "mode": "center"})
                assert away.why == "station 20 is not connected" and not away.answered
                assert len(answers) == sent
                # the console's click takes the same path into the same log
                console = ConsoleServer(desk)
                reply = await console.perform(
                    {"type": "route_cancel", "station": 18, "entry": "01"}
                )
                assert reply == {"ok": True, "reason": None,
                                 "text": "station 18: cancel route 01-11: accepted"}  # fmt: skip
                await ctc.wait_until(lambda: model.summary(18)["routes"] == [])
            finally:
                await rig.close()
        log = [(e["source"], e["command"], e["result"]) for e in desk.log.last(10)]
        assert log == [
            ("ctc", "route set 18 01 11", "accepted"),
            ("ctc", "route set 18 01 12", "rejected: route conflicts"),
            ("ctc", "route set 18 01 02",
             "refused by the CTC: station 18: no route from signal 01 to 02"),
            ("ctc", "mode center 20", "no result: station 20 is not connected"),
            ("console", "route cancel 18 01", "accepted"),
        ]  # fmt: skip

    run(main())
