"""An ACKed REQUEST_ALL is always answered, over a REAL pty: the IXL's end of its ATC link (the
code port every emulator uses, with station 18's charts) on the master side, and an ATC the test
plays with raw bytes through pyserial on the slave path. The ATC asks REQUEST_ALL once and then
acknowledges nothing until the IXL's link has failed; the IXL's state moves on meanwhile. When the
ATC behaves again it must receive an ALL_INFO with the IXL's state of that moment.
"""

from __future__ import annotations

import asyncio

from ktcs_bench.binding import LinkBinding
from ktcs_bench.codec import Frame, StreamDecoder
from ktcs_bench.emulator.code_link import CodePort
from ktcs_bench.station import load_line
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.transport import SerialTransport
from ktcs_bench.transport.endpoints import Endpoint
from ktcs_bench.type1 import LinkConfig

from .helpers import CODEC, OPS, PROFILE

RATE = 96000.0  # 10× the line rate keeps it quick; pacing is still on
CONFIG = LinkConfig(line_rate=RATE, longest_frame_data=64, delta_r=0.15, ack_timeout=0.25)


def test_an_atc_deaf_after_asking_once_gets_the_ixls_current_state_over_a_pty() -> None:
    view = load_line().view(18)
    tx, rx = link_charts(view, "ixl_to_atc")
    state: dict[str, int] = {}  # the IXL's state of its ATC link: the test plays the interlocking

    async def main() -> None:
        loop = asyncio.get_running_loop()
        link_states: asyncio.Queue[bool] = asyncio.Queue()
        port = CodePort(
            "ixl18-atc", Endpoint("pty", ""), LinkBinding(tx, rx, lambda: state),
            lambda codes: None, link_states.put_nowait, config=CONFIG,
        )  # fmt: skip
        assert port.path is not None and port.transport is not None
        acking = False
        infos: asyncio.Queue[Frame] = asyncio.Queue()
        dec = StreamDecoder(PROFILE)
        with SerialTransport(port.path, "atc", line_rate=RATE) as atc:

            def readable() -> None:
                for rec in dec.feed(atc.recv(0)):
                    if not isinstance(rec, Frame) or not rec.ok:
                        continue
                    if rec.op in (OPS["ACK"], OPS["NAK"]) or not acking:
                        continue
                    atc.send(CODEC.encode(rec.seq or 0, OPS["ACK"]))
                    if rec.op == OPS["ALL_INFO"]:
                        infos.put_nowait(rec)

            fd = atc.fileno()
            assert fd is not None
            loop.add_reader(fd, readable)
            task = asyncio.create_task(port.run())
            try:
                atc.send(CODEC.encode(0, OPS["REQUEST_ALL"], b"\x00\x00\xff\xff"))
                async with asyncio.timeout(10):
                    assert await link_states.get() is True  # our request brought it up
                    assert await link_states.get() is False  # and our deafness took it down
                # the IXL's state moves on while the ATC is deaf
                changes = {tx.codes[0].name: 1, tx.codes[5].name: 1}
                state.update(changes)
                port.update(changes)
                current = bytes(port.state[c.name] for c in tx.codes)
                assert current.count(1) == 2
                acking = True
                async with asyncio.timeout(10):
                    info = await infos.get()
                assert info.data == current
            finally:
                port.stop()
                await task
                loop.remove_reader(fd)
                port.transport.close()

    asyncio.run(asyncio.wait_for(main(), 30))
