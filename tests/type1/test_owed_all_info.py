"""An ACKed REQUEST_ALL is always answered (SPEC §3.4), on an explicit virtual clock.

The link under test is the IXL's end; the peer is an ATC the test plays frame by frame: it asks
REQUEST_ALL once, then acknowledges nothing for a few seconds, then behaves. We ACKed its request,
so the ALL_INFO is owed: a communication error must not drop it, and when it goes out it carries
the state of that moment, not the state when it was asked.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from ktcs_bench.codec import Frame, StreamDecoder
from ktcs_bench.type1 import CommunicationError, LinkConfig, LinkDown, LinkEvent, LinkUp, Type1Link

from .helpers import CODEC, CONFIG, OPS, PROFILE, provider

STEP = 0.001  # s of virtual time per step


class DeafPeer:
    """The ATC: hears our frames (decoded as they were sent, with the time), answers ACKs only
    for the data frames `acks(frame, now)` lets through."""

    def __init__(self, acks: Callable[[Frame, float], bool]) -> None:
        self.acks = acks
        self.dec = StreamDecoder(PROFILE)
        self.heard: list[tuple[float, Frame]] = []
        self.acked: list[tuple[float, Frame]] = []
        self.acks_heard: list[int] = []  # SEQs our link acknowledged

    def hear(self, data: bytes, now: float) -> bytes:
        reply = b""
        for rec in self.dec.feed(data):
            if not isinstance(rec, Frame) or not rec.ok or rec.op == OPS["NAK"]:
                continue
            if rec.op == OPS["ACK"]:
                self.acks_heard.append(rec.seq or 0)
                continue
            self.heard.append((now, rec))
            if self.acks(rec, now):
                self.acked.append((now, rec))
                reply += CODEC.encode(rec.seq or 0, OPS["ACK"])
        return reply

    def acked_all_info(self, after: float = 0.0) -> list[bytes]:
        return [f.data for t, f in self.acked if f.op == OPS["ALL_INFO"] and t >= after]


def drive(
    link: Type1Link,
    peer: DeafPeer,
    start: float,
    until: float,
    at: dict[float, Callable[[float], bytes | None]] | None = None,
) -> list[tuple[float, LinkEvent]]:
    """Run the link and the peer from `start` to `until` in steps of `STEP`; `at` holds actions
    (time -> f(now) returning bytes the peer sends, or None) run once when their time comes."""
    actions = sorted((at or {}).items())
    events: list[tuple[float, LinkEvent]] = []
    now = start
    while now < until:
        while actions and actions[0][0] <= now:
            sent = actions.pop(0)[1](now)
            if sent:
                events += [(now, e) for e in link.receive_data(sent, now)]
        deadline = link.next_deadline()
        if deadline is not None and deadline <= now:
            events += [(now, e) for e in link.handle_timer(now)]
        reply = peer.hear(link.data_to_send(now), now)
        if reply:
            events += [(now, e) for e in link.receive_data(reply, now)]
        now += STEP
    return events


def of(events: list[tuple[float, LinkEvent]], kind: type) -> list[tuple[float, LinkEvent]]:
    return [(t, e) for t, e in events if isinstance(e, kind)]


def request_all(seq: int = 0) -> bytes:
    return CODEC.encode(seq, OPS["REQUEST_ALL"], b"\x00\x00\xff\xff")


@pytest.mark.parametrize(
    ("config", "deaf_until", "down"),
    [
        (CONFIG, 3.0, "communication error"),  # our REQUEST_ALL fails first, the answer behind it
        (LinkConfig(), 8.0, "silence"),  # ACK timeout 1.7 s: 3 s of silence comes first
    ],
)
def test_peer_deaf_after_asking_once_gets_the_current_state_after_recovery(
    config: LinkConfig, deaf_until: float, down: str
) -> None:
    state = {1: 1, 2: 0, 3: 1}
    link = Type1Link(PROFILE, config, "ixl", state_provider=provider(state))
    link.handle_timer(0.0)
    peer = DeafPeer(lambda frame, now: now >= deaf_until)

    def change_state(now: float) -> None:
        state[2] = 1  # the IXL's state moves on while the ATC is deaf

    events = drive(
        link, peer, 0.0, deaf_until + 3.0, {0.01: lambda now: request_all(), 1.5: change_state}
    )

    # the link came back when the peer started acknowledging, and paid what it owed
    assert peer.acked_all_info(after=deaf_until) == [bytes([1, 1, 1])]  # the state now
    # the premise: we ACKed the request, then the deaf peer took the link down
    assert peer.acks_heard[:1] == [0]
    downs = of(events, LinkDown)
    assert downs and downs[0][1].reason == down and downs[0][0] < deaf_until  # type: ignore[attr-defined]
    # nothing owed is reported discarded: it is kept for the recovery
    for _, e in [*of(events, CommunicationError), *downs]:
        assert all(m.name != "ALL_INFO" for m in e.discarded)  # type: ignore[attr-defined]
    assert of(events, LinkUp)[-1][0] >= deaf_until and link.up
    # in order: our own REQUEST_ALL first, then the owed ALL_INFO
    after = [f.op for t, f in peer.acked if t >= deaf_until and f.op != OPS["LINK_TEST"]]
    assert after[:2] == [OPS["REQUEST_ALL"], OPS["ALL_INFO"]]
    assert link.queued == 0


def test_an_all_info_that_failed_is_sent_again_from_the_state_of_its_new_sending() -> None:
    state = {1: 1, 2: 0, 3: 1}
    link = Type1Link(PROFILE, CONFIG, "ixl", state_provider=provider(state))
    link.handle_timer(0.0)
    deaf_until = 3.0
    # the peer ACKs everything but ALL_INFO until `deaf_until`: each time the link recovers, the
    # owed ALL_INFO goes out again, and fails again, until then
    peer = DeafPeer(lambda frame, now: now >= deaf_until or frame.op != OPS["ALL_INFO"])

    def change_state(now: float) -> None:
        state[3] = 0

    events = drive(link, peer, 0.0, 5.0, {0.01: lambda now: request_all(), 0.5: change_state})

    failed = [e for _, e in of(events, CommunicationError) if e.message.name == "ALL_INFO"]  # type: ignore[attr-defined]
    assert len(failed) >= 2
    sends = [f for t, f in peer.heard if f.op == OPS["ALL_INFO"] and t < deaf_until]
    first = sends[:4]  # one frame, sent 4 times with the state when it first went out
    assert len({f.raw for f in first}) == 1 and first[0].data == bytes([1, 0, 1])
    assert sends[4:] and {f.data for f in sends[4:]} == {bytes([1, 0, 0])}  # made anew
    assert peer.acked_all_info() == [bytes([1, 0, 0])]


def test_the_answer_is_made_when_it_goes_out_not_when_it_was_asked() -> None:
    state = {1: 1, 2: 0}
    link = Type1Link(PROFILE, CONFIG, "ixl", state_provider=provider(state))
    link.handle_timer(0.0)
    peer = DeafPeer(lambda frame, now: frame.op != OPS["CHANGE"] or now >= 0.6)
    # the link is up and busy: a CHANGE outstanding, not acknowledged before 0.6 s
    link.receive_data(CODEC.encode(0, OPS["LINK_TEST"]), 0.0)
    drive(link, peer, 0.0, 0.3)
    link.send(link.message("CHANGE", items=[[2, 1]]), 0.3)

    def change_state(now: float) -> None:
        state[2] = 1

    drive(link, peer, 0.3, 1.2, {0.35: lambda now: request_all(1), 0.5: change_state})

    assert peer.acked_all_info() == [bytes([1, 1])]  # not [1, 0], the state when asked


def test_a_request_asked_again_before_it_was_answered_is_answered_once() -> None:
    link = Type1Link(PROFILE, CONFIG, "ixl", state_provider=provider({1: 1}))
    link.handle_timer(0.0)
    peer = DeafPeer(lambda frame, now: now >= 1.0)
    again = CODEC.encode(1, OPS["REQUEST_ALL"], b"\x00\x00\xff\xff")
    drive(link, peer, 0.0, 3.0, {0.01: lambda now: request_all(), 0.02: lambda now: again})
    assert peer.acks_heard[:2] == [0, 1]
    assert peer.acked_all_info() == [b"\x01"]
