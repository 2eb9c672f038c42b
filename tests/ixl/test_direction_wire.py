"""A departure that waits for its interval's permission is answered on the wire when it comes:
the CTC's CONTROL goes out over real Type II (TCP on 127.0.0.1), no CONTROL_RESULT comes back
while station 20's interlocking asks station 18 for 1820's permission, and the answer goes when
the permission arrives (SPEC §4, §6.6)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from ktcs_bench.binding import ControlLink
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.ixl import Reason
from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.transport.ixl_client import IxlClient

from .direction_pair import Pair


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


async def _until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:
    """Wait for what no event announces (the interlocking's own queue)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate():
        assert loop.time() < deadline, "condition not reached"
        await asyncio.sleep(0.005)


@pytest.mark.parametrize("given", [True, False])
def test_a_waiting_departure_is_answered_when_the_permission_comes(line: Line, given: bool) -> None:
    pair = Pair(line)
    if not given:
        assert pair.west.control("RSC181191").accepted  # 18 will not give: its route is locked
        pair.shuttle()
    rig = pair.east

    def control(name: str, value: int) -> tuple[bool, int] | None:
        result = rig.request(name, value)
        return None if result is None else (result.accepted, int(result.reason))

    link = ControlLink(
        *link_charts(rig.view, "ixl_to_ctc"), lambda: rig.ctc, control, int(Reason.UNKNOWN_CODE)
    )

    async def main() -> None:
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            async with IxlClient(20, "127.0.0.1", ctc.port, link, backoff_initial=0.02) as client:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                code = link.control_number("RSC202192")
                answer = asyncio.ensure_future(ctc.control(20, code, 1))
                await _until(lambda: bool(rig.ixl.pending()))  # asked 18; no answer yet
                await asyncio.sleep(0.05)
                assert not answer.done()
                if given:
                    pair.shuttle()  # 18 gives
                else:
                    pair.advance(3.5)  # nothing comes within 3 s
                (late,) = rig.results
                assert late.name is not None
                client.control_result(link.control_number(late.name), late.accepted,
                                      int(late.reason))  # fmt: skip
                got = await asyncio.wait_for(answer, 5.0)
        assert got.code == code
        if given:
            assert got.accepted and got.reason == 0
        else:
            assert not got.accepted and got.reason == Reason.DIRECTION
            assert got.reason_name == "direction"  # named by the profile

    asyncio.run(asyncio.wait_for(main(), 30))
