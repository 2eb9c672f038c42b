"""Type I link rules (SPEC §3.4) on the virtual clock: two real `Type1Link`s, an in-memory wire."""

from __future__ import annotations

import pytest

from ktcs_bench.errors import UsageError
from ktcs_bench.faults import CorruptFrame, Cut, DropFrame, TruncateFrame
from ktcs_bench.type1 import (
    AckSent,
    CommunicationError,
    DuplicateReceived,
    GarbageReceived,
    LinkConfig,
    LinkDown,
    LinkUp,
    Message,
    MessageReceived,
    NakReceived,
    NakSent,
    Retransmission,
    SequenceGap,
    Type1Link,
)

from .helpers import CODEC, CONFIG, OPS, PROFILE, data_frames, frames_on, make_pair


def settled(**kw: object):  # type: ignore[no-untyped-def]
    """A pair that has come up and finished its start-up REQUEST_ALL/ALL_INFO exchange."""
    a, b, bench = make_pair({1: 1, 2: 0, 3: 1}, {1: 0, 2: 1}, **kw)  # type: ignore[arg-type]
    bench.run_for(0.5)
    assert a.up and b.up and a.queued == 0 and b.queued == 0
    return a, b, bench


def received(bench, link, op="CHANGE"):  # type: ignore[no-untyped-def]
    return [e for e in bench.of(link, MessageReceived) if e.message.name == op]


def change(link: Type1Link, code: int = 3, state: int = 1) -> Message:
    return link.message("CHANGE", items=[[code, state]])


def test_default_timers_follow_the_line_rate() -> None:
    t = LinkConfig().resolve(PROFILE)
    byte = 10 / 9600
    longest = PROFILE.frame_size(PROFILE.max_data) * byte
    assert t.byte_time == pytest.approx(byte)
    assert t.delta_r == pytest.approx(1.5 * longest + 0.020)
    assert t.ack_timeout == pytest.approx(t.delta_r + 11 * byte + 0.050)
    assert (t.link_test_period, t.link_down_after, t.max_transmissions) == (1.0, 3.0, 4)
    assert LinkConfig(delta_r=0.3, ack_timeout=0.5).resolve(PROFILE).ack_timeout == 0.5


@pytest.mark.requirement("T1-RESYNC-01", "T1-CODES-01")
def test_start_up_links_come_up_and_rebuild_state_from_all_info() -> None:
    a, b, bench = settled()
    for link, peer_state in ((a, [0, 1]), (b, [1, 0, 1])):
        assert len(bench.of(link, LinkUp)) == 1
        (req,) = received(bench, link, "REQUEST_ALL")
        assert req.fields == {"start": 0, "count": 0xFFFF}
        (info,) = received(bench, link, "ALL_INFO")
        assert info.fields["statuses"] == peer_state


@pytest.mark.requirement("T1-ARQ-01")
def test_message_delivered_once_and_acked() -> None:
    a, b, bench = settled()
    bench.send(a, change(a))
    bench.run_for(0.2)
    (got,) = received(bench, b)
    assert got.fields == {"items": [[3, 1]]}
    (frame,) = data_frames(bench.ab, "CHANGE")
    assert any(f.op == OPS["ACK"] and f.seq == frame.seq for f in frames_on(bench.ba))
    assert a.queued == 0


@pytest.mark.requirement("T1-CRC-02")
def test_1_crc_error_nak_then_same_frame_again() -> None:
    a, b, bench = settled()
    bench.fault(bench.ab, CorruptFrame(-5, 0x10))  # the CRC's low byte of a's next frame
    bench.send(a, change(a))
    bench.run_for(0.5)
    (nak,) = bench.of(b, NakSent)
    assert nak.reason == 1
    (nak_in,) = bench.of(a, NakReceived)
    assert nak_in.reason == 1
    (rt,) = bench.of(a, Retransmission)
    assert rt.cause == "nak" and rt.transmission == 2
    first, second = data_frames(bench.ab, "CHANGE")
    assert first.raw == second.raw  # same frame, same SEQ
    assert len(received(bench, b)) == 1


@pytest.mark.requirement("T1-DR-01")
def test_2_no_complete_frame_within_delta_r_nak_reason_2() -> None:
    a, b, bench = settled()
    bench.fault(bench.ab, TruncateFrame(4))  # a's next frame loses its last 4 bytes
    sent_at = bench.now
    bench.send(a, change(a))
    bench.run_for(0.5)
    ((t_nak, nak),) = [(t, e) for t, n, e in bench.events if n == "b" and isinstance(e, NakSent)]
    assert nak.reason == 2 and nak.detail.startswith("truncated")
    assert t_nak >= sent_at + b.timers.delta_r
    (rt,) = bench.of(a, Retransmission)
    assert rt.cause == "nak"
    assert len(received(bench, b)) == 1


@pytest.mark.requirement("T1-ARQ-02", "T1-ARQ-04")
def test_3_lost_ack_timeout_retransmits_same_seq_duplicate_not_redelivered() -> None:
    a, b, bench = settled()
    bench.fault(bench.ba, DropFrame())  # b's next frame: the ACK of a's CHANGE
    bench.send(a, change(a))
    bench.run_for(1.0)
    (rt,) = bench.of(a, Retransmission)
    assert rt.cause == "timeout" and rt.transmission == 2
    first, second = data_frames(bench.ab, "CHANGE")
    assert first.raw == second.raw
    assert len(received(bench, b)) == 1
    (dup,) = bench.of(b, DuplicateReceived)
    assert dup.seq == first.seq
    assert [e.seq for e in bench.of(b, AckSent)].count(first.seq) == 2
    assert a.queued == 0 and not bench.of(a, CommunicationError)


@pytest.mark.requirement("T1-ARQ-03")
def test_communication_error_after_exactly_three_retransmissions() -> None:
    a, b, bench = settled()
    bench.fault(bench.ab, Cut())  # a's transmitter dies; its frames never arrive
    msg = change(a)
    queued_behind = change(a, 4, 0)
    bench.send(a, msg)
    bench.send(a, queued_behind)
    bench.run_for(1.5)
    frames = data_frames(bench.ab, "CHANGE")
    assert len(frames) == 4  # 1 transmission + 3 retransmissions, counted on the wire
    assert len({f.raw for f in frames}) == 1
    retransmissions = [e for e in bench.of(a, Retransmission) if e.message == msg]
    assert [e.transmission for e in retransmissions] == [2, 3, 4]
    (err,) = bench.of(a, CommunicationError)
    assert (err.message, err.transmissions, err.discarded) == (msg, 4, (queued_behind,))
    assert bench.of(a, LinkDown) == [LinkDown("communication error")]
    assert not received(bench, b)


@pytest.mark.requirement("T1-ARQ-04")
def test_duplicate_seq_is_acked_again_but_not_delivered_twice() -> None:
    link = Type1Link(PROFILE, CONFIG, "rx")
    frame = CODEC.encode(0x42, OPS["CHANGE"], bytes.fromhex("050001"))
    first = link.receive_data(frame, 1.0)
    assert [e.fields for e in first if isinstance(e, MessageReceived)] == [{"items": [[5, 1]]}]
    ack = CODEC.encode(0x42, OPS["ACK"])
    assert link.data_to_send(1.0).startswith(ack)
    again = link.receive_data(frame, 1.2)
    assert not [e for e in again if isinstance(e, MessageReceived)]
    assert [type(e) for e in again] == [AckSent, DuplicateReceived]
    assert link.data_to_send(1.2) == ack  # ACKed again
    nxt = link.receive_data(CODEC.encode(0x43, OPS["CHANGE"], bytes.fromhex("050000")), 1.3)
    assert [e.fields for e in nxt if isinstance(e, MessageReceived)] == [{"items": [[5, 0]]}]


@pytest.mark.requirement("T1-FRAME-03")
def test_resync_after_garbage() -> None:
    a, b, bench = settled()
    junk = bytes.fromhex("ff 02 ff 7f 00 13 02 05 00 99 03 55 aa 02")  # false STXs, silly LENs
    frame = CODEC.encode(0x50, OPS["CHANGE"], bytes.fromhex("070001"))
    bench.inject(bench.ab, junk + frame + b"\x00\x03")
    bench.run_for(2.0)
    assert [e.fields for e in received(bench, b)] == [{"items": [[7, 1]]}]
    assert bench.of(b, GarbageReceived)
    assert b.up


@pytest.mark.requirement("T1-FRAME-04")
def test_unknown_opcode_and_bad_payload_nak_reason_3() -> None:
    a, b, bench = settled()
    bench.inject(bench.ab, CODEC.encode(0x60, 0x0777, b"\x01"))
    bench.run_for(0.1)
    bench.inject(bench.ab, CODEC.encode(0x61, OPS["CHANGE"], b"\x01\x02"))  # not 3-byte items
    bench.run_for(0.1)
    assert [(e.seq, e.reason) for e in bench.of(b, NakSent)] == [(0x60, 3), (0x61, 3)]
    assert "unknown opcode 0x0777" in bench.of(b, NakSent)[0].detail
    assert not received(bench, b)


def test_ack_and_nak_are_never_acknowledged() -> None:
    a, b, bench = settled()
    bench.inject(bench.ab, CODEC.encode(0x70, OPS["ACK"]))
    bench.inject(bench.ab, CODEC.encode(0x71, OPS["NAK"], b"\x01"))
    bench.run_for(0.2)
    replies = [f for f in frames_on(bench.ba) if f.seq in (0x70, 0x71)]
    assert replies == []


@pytest.mark.requirement("T1-LINK-01")
def test_link_test_when_idle_and_not_delivered() -> None:
    a, b, bench = settled()
    before = len(data_frames(bench.ab, "LINK_TEST"))
    bench.run_for(5.0)
    tests = data_frames(bench.ab, "LINK_TEST")[before:]
    assert 4 <= len(tests) <= 6  # one a second of idleness
    assert not bench.of(a, LinkDown) and not bench.of(b, LinkDown)
    assert not received(bench, b, "LINK_TEST")


def test_busy_direction_sends_no_link_test() -> None:
    a, b, bench = settled()
    before = len(data_frames(bench.ab, "LINK_TEST"))
    for i in range(12):
        bench.send(a, change(a, 10 + i))
        bench.run_for(0.4)
    assert len(data_frames(bench.ab, "LINK_TEST")) == before


@pytest.mark.requirement("T1-LINK-01", "T1-RESYNC-01")
def test_link_down_after_silence_and_up_again_with_full_resync() -> None:
    state_a = {1: 1, 2: 0, 3: 1}
    # default timers (ACK timeout 1.7 s): 3 s of silence comes before a LINK_TEST's 4th failure
    a, b, bench = make_pair(state_a, {1: 0, 2: 1}, config=LinkConfig())
    bench.run_for(0.5)
    bench.fault(bench.ab, Cut())
    bench.fault(bench.ba, Cut())
    bench.run_for(3.6)
    assert bench.of(a, LinkDown)[-1].reason == "silence"
    assert bench.of(b, LinkDown)[-1].reason == "silence"
    assert not a.up and not b.up
    state_a.update({2: 1, 4: 1})  # the field changed while the link was down
    n_info = len(received(bench, b, "ALL_INFO"))
    bench.ab.restore()
    bench.ba.restore()
    bench.run_for(4.0)
    assert a.up and b.up
    assert len(bench.of(a, LinkUp)) == len(bench.of(b, LinkUp)) == 2
    assert len(received(bench, a, "REQUEST_ALL")) == 2
    infos = received(bench, b, "ALL_INFO")[n_info:]
    assert infos and infos[-1].fields["statuses"] == [1, 1, 1, 1]


def test_one_sided_communication_error_rebuilds_both_views() -> None:
    a, b, bench = settled()
    bench.fault(bench.ab, Cut())
    bench.send(a, change(a))
    bench.run_for(1.2)
    assert bench.of(a, CommunicationError) and bench.of(a, LinkDown) and not bench.of(b, LinkDown)
    bench.ab.restore()
    n_a, n_b = len(received(bench, a, "ALL_INFO")), len(received(bench, b, "ALL_INFO"))
    bench.run_for(1.5)
    assert a.up and b.up
    assert len(received(bench, a, "ALL_INFO")) > n_a  # a asked on its recovery
    assert len(received(bench, b, "ALL_INFO")) > n_b  # b asked too: gap or peer's REQUEST_ALL
    assert bench.of(b, SequenceGap) or len(received(bench, b, "REQUEST_ALL")) >= 2


def test_seq_wraps_modulo_256() -> None:
    a, b, bench = settled()
    for i in range(300):
        bench.send(a, change(a, i % 1000))
    bench.run_for(30.0, stop=lambda: a.queued == 0)
    assert a.queued == 0
    got = [e.fields["items"][0][0] for e in received(bench, b)]
    assert got == list(range(300))
    assert not bench.of(b, DuplicateReceived) and not bench.of(b, SequenceGap)


def test_the_link_owns_ack_and_nak() -> None:
    link = Type1Link(PROFILE, CONFIG)
    with pytest.raises(UsageError):
        link.send(Message(OPS["ACK"]), 0.0)
    with pytest.raises(UsageError):
        link.message("NO_SUCH_OP")


def test_sans_io_contract_step_by_step() -> None:
    link = Type1Link(PROFILE, CONFIG, "x")
    assert link.next_deadline() is None
    assert link.handle_timer(10.0) == []
    probe = link.data_to_send(10.0)  # the line opened: a LINK_TEST announces us
    assert probe == CODEC.encode(0, OPS["LINK_TEST"])
    deadline = link.next_deadline()
    assert deadline == pytest.approx(10.0 + 11 * link.timers.byte_time + link.timers.ack_timeout)
    events = link.receive_data(CODEC.encode(0, OPS["ACK"]), 10.05)
    assert [type(e) for e in events] == [LinkUp, type(events[1])] and events[1].seq == 0
    assert link.data_to_send(10.05)[4:6] == OPS["REQUEST_ALL"].to_bytes(2, "little")
