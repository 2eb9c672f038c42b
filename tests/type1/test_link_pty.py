"""Type I link rules over REAL ptys (os.openpty + pyserial on the slave path), wall clock, asyncio.

The link under test runs in a `LinkRunner` on the slave side through pyserial; the test plays the
peer on the master side with raw bytes (`RawPeer`), so it can corrupt, cut, withhold and repeat
frames exactly. One test runs two links against each other. No timing assertions: only what went
over the wire and which events came out.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from ktcs_bench.codec import Frame, StreamDecoder
from ktcs_bench.transport import LinkRunner, PtyTransport, SerialTransport
from ktcs_bench.type1 import (
    CommunicationError,
    DuplicateReceived,
    GarbageReceived,
    LinkConfig,
    LinkDown,
    LinkUp,
    MessageReceived,
    NakSent,
    Type1Link,
)

from .helpers import CODEC, OPS, PROFILE, provider

RATE = 96000.0  # 10× the line rate keeps the suite quick; pacing is still on
CONFIG = LinkConfig(line_rate=RATE, longest_frame_data=64, delta_r=0.15, ack_timeout=0.25)


class RawPeer:
    """The master side of the pty, spoken byte by byte by the test."""

    def __init__(self, transport: PtyTransport) -> None:
        self.t = transport
        self.dec = StreamDecoder(PROFILE)
        self.frames: asyncio.Queue[Frame] = asyncio.Queue()
        self.log: list[Frame] = []
        self.auto_ack_link_test = True

    def _readable(self) -> None:
        for rec in self.dec.feed(self.t.recv(0)):
            if isinstance(rec, Frame):
                self.log.append(rec)
                if self.auto_ack_link_test and rec.ok and rec.op == OPS["LINK_TEST"]:
                    self.t.send(CODEC.encode(rec.seq or 0, OPS["ACK"]))
                    continue
                self.frames.put_nowait(rec)

    async def frame(self, timeout: float = 3.0) -> Frame:
        async with asyncio.timeout(timeout):
            return await self.frames.get()

    def send(self, data: bytes) -> None:
        self.t.send(data)

    def ack(self, seq: int) -> None:
        self.send(CODEC.encode(seq, OPS["ACK"]))


@contextlib.asynccontextmanager
async def link_and_peer(config: LinkConfig = CONFIG) -> AsyncIterator[tuple[LinkRunner, RawPeer]]:
    loop = asyncio.get_running_loop()
    with (
        PtyTransport("peer", line_rate=RATE) as master,
        SerialTransport(master.path, "dut", line_rate=RATE) as slave,
    ):
        peer = RawPeer(master)
        loop.add_reader(master.fileno(), peer._readable)  # type: ignore[arg-type]
        link = Type1Link(PROFILE, config, "dut", state_provider=provider({1: 1, 2: 0}))
        runner = LinkRunner(link, slave)
        task = asyncio.create_task(runner.run())
        try:
            yield runner, peer
        finally:
            runner.stop()
            await task
            loop.remove_reader(master.fileno())  # type: ignore[arg-type]


async def bring_up(runner: LinkRunner, peer: RawPeer) -> int:
    """ACK the link's REQUEST_ALL on coming up; return the SEQ its next data frame will carry."""
    peer.send(CODEC.encode(0x20, OPS["LINK_TEST"]))  # our own probe brings the link up
    assert (await peer.frame()).op == OPS["ACK"]
    await runner.next_event(LinkUp, timeout=3)
    req = await peer.frame()
    assert req.ok and req.op == OPS["REQUEST_ALL"]
    peer.ack(req.seq or 0)
    return ((req.seq or 0) + 1) % 256


def run(coro: object) -> None:
    asyncio.run(asyncio.wait_for(coro, 20))  # type: ignore[arg-type]


def test_two_links_over_a_pty_come_up_and_exchange_state() -> None:
    async def main() -> None:
        with PtyTransport("a", line_rate=RATE) as ta, SerialTransport(ta.path, "b", RATE) as tb:
            a = Type1Link(PROFILE, CONFIG, "a", state_provider=provider({1: 1, 2: 1, 3: 0}))
            b = Type1Link(PROFILE, CONFIG, "b", state_provider=provider({1: 0, 2: 1}))
            ra, rb = LinkRunner(a, ta), LinkRunner(b, tb)
            tasks = [asyncio.create_task(r.run()) for r in (ra, rb)]
            info_a = await ra.next_event(MessageReceived, timeout=5)
            while info_a.message.name != "ALL_INFO":  # type: ignore[union-attr]
                info_a = await ra.next_event(MessageReceived, timeout=5)
            info_b = await rb.next_event(MessageReceived, timeout=5)
            while info_b.message.name != "ALL_INFO":  # type: ignore[union-attr]
                info_b = await rb.next_event(MessageReceived, timeout=5)
            assert info_a.fields["statuses"] == [0, 1]  # type: ignore[union-attr]
            assert info_b.fields["statuses"] == [1, 1, 0]  # type: ignore[union-attr]
            for i in range(20):
                ra.send(a.message("CHANGE", items=[[i, i & 1]]))
            got = []
            while len(got) < 20:
                ev = await rb.next_event(MessageReceived, timeout=5)
                got.append(ev.fields["items"][0][0])  # type: ignore[union-attr]
            assert got == list(range(20))
            for r in (ra, rb):
                r.stop()
            await asyncio.gather(*tasks)

    run(main())


def test_1_crc_error_is_naked_and_nak_brings_the_same_frame_again() -> None:
    async def main() -> None:
        async with link_and_peer() as (runner, peer):
            seq = await bring_up(runner, peer)
            # receiving side: a frame with a bad CRC is answered NAK reason 1
            bad = bytearray(CODEC.encode(0x30, OPS["CHANGE"], bytes.fromhex("030001")))
            bad[-5] ^= 0xFF
            peer.send(bytes(bad))
            nak = await peer.frame()
            assert (nak.op, nak.data) == (OPS["NAK"], b"\x01")
            assert (await runner.next_event(NakSent, timeout=3)).reason == 1  # type: ignore[union-attr]
            # sending side: our NAK makes the link send the same frame with the same SEQ
            runner.send(runner.link.message("CHANGE", items=[[9, 1]]))
            first = await peer.frame()
            assert first.ok and first.seq == seq
            peer.send(CODEC.encode(seq, OPS["NAK"], b"\x01"))
            again = await peer.frame()
            assert again.raw == first.raw
            peer.ack(seq)
            # Stop-and-wait: the next frame goes out only once our ACK is taken. Had the link
            # not taken it, the first frame would come again before this one.
            runner.send(runner.link.message("CHANGE", items=[[10, 1]]))
            after = await peer.frame()
            assert after.ok and after.seq == (seq + 1) % 256 and after.raw != first.raw

    run(main())


def test_2_incomplete_frame_within_delta_r_is_naked_reason_2() -> None:
    async def main() -> None:
        async with link_and_peer() as (runner, peer):
            await bring_up(runner, peer)
            frame = CODEC.encode(0x31, OPS["CHANGE"], bytes.fromhex("030001"))
            peer.send(frame[:-4])  # STX seen, the rest never comes
            nak = await peer.frame()
            assert (nak.op, nak.data) == (OPS["NAK"], b"\x02")
            peer.send(frame)  # the retransmission is accepted
            assert (await peer.frame()).op == OPS["ACK"]
            ev = await runner.next_event(MessageReceived, timeout=3)
            assert ev.fields == {"items": [[3, 1]]}  # type: ignore[union-attr]

    run(main())


def test_3_no_ack_retransmits_same_seq_then_communication_error_after_3() -> None:
    async def main() -> None:
        async with link_and_peer() as (runner, peer):
            seq = await bring_up(runner, peer)
            runner.send(runner.link.message("CHANGE", items=[[4, 1]]))
            sent = [await peer.frame() for _ in range(4)]  # we never ACK
            assert {f.raw for f in sent} == {sent[0].raw} and sent[0].seq == seq
            err = await runner.next_event(CommunicationError, timeout=3)
            assert err.transmissions == 4  # type: ignore[union-attr]
            assert (await runner.next_event(LinkDown, timeout=1)).reason == "communication error"  # type: ignore[union-attr]
            # A 5th transmission would have been due when the link gave up instead: our probe,
            # sent now, is answered after everything the link wrote before it.
            peer.send(CODEC.encode(0x40, OPS["LINK_TEST"]))
            while not ((f := await peer.frame()).op == OPS["ACK"] and f.seq == 0x40):
                pass
            changes = [f for f in peer.log if f.op == OPS["CHANGE"]]
            assert len(changes) == 4  # counted on the wire: 1 + 3 retransmissions

    run(main())


def test_duplicate_seq_acked_again_not_delivered_twice_and_resync_after_garbage() -> None:
    async def main() -> None:
        async with link_and_peer() as (runner, peer):
            await bring_up(runner, peer)
            frame = CODEC.encode(0x21, OPS["CHANGE"], bytes.fromhex("070001"))
            peer.send(b"\x55\xaa\x02\x08\x00" + frame)  # garbage with a false STX first
            ack = await peer.frame()
            assert (ack.op, ack.seq) == (OPS["ACK"], 0x21)
            first = await runner.next_event(MessageReceived, timeout=3)
            assert first.seq == 0x21  # type: ignore[union-attr]
            peer.send(frame)
            ack2 = await peer.frame()
            assert (ack2.op, ack2.seq) == (OPS["ACK"], 0x21)
            # the next frame's delivery shows the link is past the repeat: what it delivered
            # in between is all it ever will for it
            peer.send(CODEC.encode(0x22, OPS["CHANGE"], bytes.fromhex("090001")))
            between: list[object] = []
            while not isinstance(ev := await runner.next_event(timeout=3), MessageReceived):
                between.append(ev)
            assert ev.seq == 0x22  # not a second delivery of 0x21
            dups = [d.seq for d in between if isinstance(d, DuplicateReceived)]
            assert dups == [0x21]
            assert len([f for f in peer.log if f.op == OPS["ACK"] and f.seq == 0x21]) == 2

    run(main())


def test_garbage_is_reported_and_the_frame_behind_it_delivered() -> None:
    async def main() -> None:
        async with link_and_peer() as (runner, peer):
            await bring_up(runner, peer)
            frame = CODEC.encode(0x21, OPS["CHANGE"], bytes.fromhex("080001"))
            peer.send(b"\x55\xaa\x02\x08\x00" + frame)
            garbage = await runner.next_event(GarbageReceived, timeout=3)
            assert garbage.raw == b"\x55\xaa\x02\x08\x00"  # type: ignore[union-attr]
            got = await runner.next_event(MessageReceived, timeout=3)
            assert got.fields == {"items": [[8, 1]]}  # type: ignore[union-attr]

    run(main())


def test_link_test_when_idle_then_down_after_silence_and_up_with_request_all() -> None:
    config = LinkConfig(
        line_rate=RATE, longest_frame_data=64, link_test_period=0.3, delta_r=0.15, ack_timeout=2.0
    )

    async def main() -> None:
        async with link_and_peer(config) as (runner, peer):
            await bring_up(runner, peer)
            peer.auto_ack_link_test = False
            test = await peer.frame()  # idle for 0.3 s: a LINK_TEST
            assert test.op == OPS["LINK_TEST"]
            # we answer nothing: after 3 link periods of silence the link is down
            assert (await runner.next_event(LinkDown, timeout=3)).reason == "silence"  # type: ignore[union-attr]
            peer.ack(test.seq or 0)  # the peer is back
            await runner.next_event(LinkUp, timeout=3)
            req = await peer.frame()
            assert req.op == OPS["REQUEST_ALL"] and req.data == b"\x00\x00\xff\xff"
            peer.ack(req.seq or 0)
            peer.send(CODEC.encode(0x21, OPS["REQUEST_ALL"], b"\x00\x00\xff\xff"))
            assert (await peer.frame()).op == OPS["ACK"]
            info = await peer.frame()
            assert info.op == OPS["ALL_INFO"] and info.data == b"\x01\x00"
            peer.ack(info.seq or 0)

    run(main())
