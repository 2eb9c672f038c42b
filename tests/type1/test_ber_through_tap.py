"""SPEC §9, second bullet, on real parts: two Type I links on real ptys, joined by a tap
(`tap.PtyTap`) that injects bit errors (BER 1e-3) both ways, and drops bytes and inserts garbage
(false STX included) every few messages. Thousands of frames: every message is delivered once and
intact, or its sender reports a communication error for it; the test counts corrupted and
duplicated deliveries and asserts both are zero."""

from __future__ import annotations

import asyncio
import random
from collections import Counter
from typing import Any

from ktcs_bench.faults import BitErrors, DropBytes, InsertGarbage
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.transport.aio import LinkRunner
from ktcs_bench.transport.serialport import SerialTransport
from ktcs_bench.type1 import CommunicationError, LinkConfig, LinkDown, MessageReceived, Type1Link

from .helpers import PROFILE

MESSAGES_PER_DIRECTION = 2000
# unpaced ptys; the timers are those of a 96,000 bit/s line carrying short frames
CONFIG = LinkConfig(line_rate=96_000, longest_frame_data=64)


class Direction:
    def __init__(self) -> None:
        self.sent: dict[int, bytes] = {}
        self.delivered: Counter[int] = Counter()
        self.reported: set[int] = set()
        self.corrupted = 0

    def settled(self) -> bool:
        return all(i in self.delivered or i in self.reported for i in self.sent)


def test_delivered_once_and_intact_or_communication_error_through_a_tap() -> None:
    rng = random.Random(7)
    tap = PtyTap(names=("a", "b"), profile=PROFILE, seed=11, control=None).start()
    flows = {"a": Direction(), "b": Direction()}  # keyed by sender

    def ident_of(data: bytes) -> int:
        return int.from_bytes(data[:2], "little")

    async def main() -> dict[str, Any]:
        links = {end: Type1Link(PROFILE, CONFIG, end) for end in ("a", "b")}
        transports = {end: SerialTransport(tap.paths[end], end, None) for end in ("a", "b")}
        stats: dict[str, Any] = {"comm_errors": 0}

        def sink(end: str):  # type: ignore[no-untyped-def]
            other = "b" if end == "a" else "a"

            def on_event(now: float, event: Any) -> None:
                if isinstance(event, MessageReceived) and event.message.name == "CHANGE":
                    flow, data = flows[other], event.message.data
                    if flow.sent.get(ident_of(data)) != data:
                        flow.corrupted += 1
                    else:
                        flow.delivered[ident_of(data)] += 1
                elif isinstance(event, CommunicationError | LinkDown):
                    stats["comm_errors"] += isinstance(event, CommunicationError)
                    lost = list(getattr(event, "discarded", ()))
                    if isinstance(event, CommunicationError):
                        lost.append(event.message)
                    for msg in lost:
                        if msg.name == "CHANGE":
                            flows[end].reported.add(ident_of(msg.data))

            return on_event

        runners = {end: LinkRunner(links[end], transports[end], sink(end)) for end in ("a", "b")}
        tasks = [asyncio.ensure_future(r.run()) for r in runners.values()]
        await asyncio.sleep(0.05)  # the runners start on the loop before anything is sent
        tap.inject(BitErrors(1e-3))
        try:
            for k in range(MESSAGES_PER_DIRECTION):
                for end in ("a", "b"):
                    ident = (k << 1) | (end == "b")
                    items = [[ident, ident & 0xFF]] + [
                        [rng.randrange(0x10000), rng.randrange(256)]
                        for _ in range(rng.randint(0, 5))
                    ]
                    while links[end].queued > 3:  # an application keeps its queue short
                        await asyncio.sleep(0.002)
                    msg = links[end].message("CHANGE", items=items)
                    flows[end].sent[ident] = msg.data
                    runners[end].send(msg)
                if k % 50 == 25:
                    tap.inject(DropBytes(rng.randint(1, 6), direction=rng.choice(["a>b", "b>a"])))
                if k % 50 == 0:
                    junk = bytes([0x02, rng.randrange(256), 0]) + rng.randbytes(rng.randint(1, 8))
                    tap.inject(InsertGarbage(junk, direction=rng.choice(["a>b", "b>a"])))
            async with asyncio.timeout(240):
                while not all(f.settled() for f in flows.values()):
                    await asyncio.sleep(0.1)
        finally:
            for r in runners.values():
                r.stop()
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            for t in transports.values():
                t.close()
        return stats

    try:
        stats = asyncio.run(main())
        faults = {d: tap.injectors[d].stats for d in tap.directions}
    finally:
        tap.stop()
    for end, flow in flows.items():
        duplicated = sum(1 for n in flow.delivered.values() if n > 1)
        assert flow.corrupted == 0, f"{end}: {flow.corrupted} corrupted deliveries"
        assert duplicated == 0, f"{end}: {duplicated} messages delivered twice"
        assert len(flow.sent) == MESSAGES_PER_DIRECTION
        assert all(i in flow.delivered or i in flow.reported for i in flow.sent)
        assert len(flow.delivered) > MESSAGES_PER_DIRECTION * 0.9, "the line was not that bad"
    # the faults really happened
    assert all(s.bits_flipped > 20 for s in faults.values()), faults
    print(f"\nthrough the tap: {stats['comm_errors']} communication errors; faults {faults}")
