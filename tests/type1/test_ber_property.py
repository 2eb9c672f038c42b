"""SPEC §9, second bullet: with bit errors (BER 1e-3), dropped bytes and garbage on both directions
of a Type I link, every message is delivered once and intact, or the link reports a communication
error for it -- none is delivered corrupted or twice. Virtual clock, fixed seeds, thousands of frames.
"""

from __future__ import annotations

import random
from collections import Counter
from dataclasses import dataclass, field

import pytest

from ktcs_bench.faults import BitErrors, ByteLoss, FaultInjector, Noise
from ktcs_bench.transport.virtual import VirtualBench
from ktcs_bench.type1 import (
    CommunicationError,
    LinkDown,
    Message,
    MessageReceived,
    Type1Link,
)

from .helpers import CONFIG, PROFILE

MESSAGES_PER_DIRECTION = 3000
STATE = {"a": bytes(range(40)), "b": bytes(range(100, 140))}


@dataclass
class Ledger:
    """What one direction's application sent, and what the other end's application got."""

    sent: dict[int, bytes] = field(default_factory=dict)
    delivered: Counter[int] = field(default_factory=Counter)
    reported: set[int] = field(default_factory=set)
    corrupted: int = 0

    def payload(self, link: Type1Link, ident: int, rng: random.Random) -> Message:
        items = [[ident, ident & 0xFF], [ident ^ 0xA5A5, 0x5A]]
        items += [[rng.randrange(0x10000), rng.randrange(256)] for _ in range(rng.randint(0, 4))]
        msg = link.message("CHANGE", items=items)
        self.sent[ident] = msg.data
        return msg

    def got(self, msg: Message) -> None:
        ident = int.from_bytes(msg.data[:2], "little")
        if self.sent.get(ident) != msg.data:
            self.corrupted += 1
        else:
            self.delivered[ident] += 1

    def lost(self, msg: Message) -> None:
        if msg.name == "CHANGE":
            self.reported.add(int.from_bytes(msg.data[:2], "little"))


@pytest.mark.requirement("T1-ARQ-05")
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_delivered_once_and_intact_or_communication_error(seed: int) -> None:
    faults = {d: FaultInjector.seeded(PROFILE, seed * 10 + i) for i, d in enumerate(("ab", "ba"))}
    for injector in faults.values():
        # bit errors; a byte lost now and then; a burst of 1..12 random bytes (half of them with
        # a false STX) after about one chunk in fifty (the links hand ~17-byte chunks to the wire)
        for fault in (BitErrors(1e-3), ByteLoss(2e-4), Noise(1.2e-3)):
            injector.apply(fault, 0.0)
    a = Type1Link(PROFILE, CONFIG, "a", state_provider=lambda s, c: STATE["a"])
    b = Type1Link(PROFILE, CONFIG, "b", state_provider=lambda s, c: STATE["b"])
    bench = VirtualBench(a, b, faults_ab=faults["ab"], faults_ba=faults["ba"])
    ledgers = {"a": Ledger(), "b": Ledger()}  # keyed by sender
    rng = random.Random(seed)
    counts = {"a": 0, "b": 0}
    info_ok = info_bad = 0
    seen = 0

    while min(counts.values()) < MESSAGES_PER_DIRECTION or a.queued or b.queued:
        for name, link in (("a", a), ("b", b)):
            if link.queued == 0 and counts[name] < MESSAGES_PER_DIRECTION:
                bench.send(link, ledgers[name].payload(link, counts[name], rng))
                counts[name] += 1
        bench.run_for(5.0, stop=lambda: a.queued == 0 or b.queued == 0)
        for _, at, event in bench.events[seen:]:
            peer = "b" if at == "a" else "a"
            if isinstance(event, MessageReceived):
                if event.message.name == "CHANGE":
                    ledgers[peer].got(event.message)
                elif event.message.name == "ALL_INFO":
                    if event.message.data == STATE[peer]:
                        info_ok += 1
                    else:
                        info_bad += 1
            elif isinstance(event, CommunicationError):
                for msg in (event.message, *event.discarded):
                    ledgers[at].lost(msg)
            elif isinstance(event, LinkDown):
                for msg in event.discarded:
                    ledgers[at].lost(msg)
        seen = len(bench.events)

    stats = [f.stats for f in faults.values()]
    # the line really was noisy, in every way
    assert sum(s.bits_flipped for s in stats) > 500
    assert sum(s.bytes_dropped for s in stats) > 10
    assert sum(s.garbage_inserted for s in stats) > 500
    for name, ledger in ledgers.items():
        duplicated = sum(1 for n in ledger.delivered.values() if n > 1)
        missing = [i for i in ledger.sent if not ledger.delivered[i] and i not in ledger.reported]
        assert ledger.corrupted == 0, f"{name}: {ledger.corrupted} corrupted deliveries"
        assert duplicated == 0, f"{name}: {duplicated} messages delivered twice"
        assert missing == [], f"{name}: lost without a communication error: {missing[:10]}"
        assert len(ledger.delivered) > 0.9 * MESSAGES_PER_DIRECTION
    assert info_bad == 0 and info_ok >= 2
