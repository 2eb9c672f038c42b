"""Sans-I/O tests of the Type II sessions: both ends wired in memory, an explicit clock."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from ktcs_bench.codec import FrameCodec, StreamDecoder, get_profile
from ktcs_bench.errors import UsageError
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ctc_side import CtcConnection
from ktcs_bench.type2.ixl_side import IxlSession

PROFILE = get_profile("ktcs-type2")
CODEC = FrameCodec(PROFILE)


def frames(data: bytes) -> list:
    out = StreamDecoder(PROFILE).feed(data)
    assert all(getattr(f, "ok", False) for f in out), out
    return out


class Wire:
    """An IXL and a CTC connection joined by a lossless in-memory pipe, plus a manual clock."""

    def __init__(
        self, station: int = 20, config: Type2Config | None = None, start: float = 0.0
    ) -> None:
        self.now = start
        self.ixl = IxlSession(station, self.now, config)
        self.ctc = CtcConnection(self.now, config)
        self.ixl_events: list[ev.SessionEvent] = []
        self.ctc_events: list[ev.SessionEvent] = []
        self.damage: Callable[[bytes], bytes] | None = None  # applied to each IXL -> CTC frame

    def pump(self) -> None:
        """Deliver everything pending in both directions until both are quiet."""
        while True:
            a = self.ixl.data_to_send()
            b = self.ctc.data_to_send()
            if not a and not b:
                return
            if a and self.damage is not None:
                a = b"".join(self.damage(f.raw) for f in frames(a))
            if a:
                self.ctc_events += self.ctc.receive_data(a, self.now)
            if b:
                self.ixl_events += self.ixl.receive_data(b, self.now)

    def advance(self, dt: float, pump: bool = True) -> None:
        """Move the clock forward in steps, honouring both sessions' deadlines."""
        end = self.now + dt
        while True:
            deadlines = [d for d in (self.ixl.next_deadline(), self.ctc.next_deadline()) if d]
            nxt = min(deadlines, default=end)
            if nxt > end:
                break
            self.now = max(self.now, nxt)
            self.ixl_events += self.ixl.handle_timer(self.now)
            self.ctc_events += self.ctc.handle_timer(self.now)
            if pump:
                self.pump()
            else:
                self.ixl.data_to_send()
                self.ctc.data_to_send()
            if self.ixl.closed and self.ctc.closed:
                break
        self.now = end

    def open(self, full: list[tuple[int, int]] | None = None) -> None:
        self.pump()
        req = [e for e in self.ctc_events if isinstance(e, ev.IdentRequested)]
        assert req == [ev.IdentRequested(self.ixl.station, 1)]
        self.ctc.accept(self.now)
        self.pump()
        assert ev.IdentAccepted(self.ixl.station) in self.ixl_events
        if full is not None:
            self.ixl.send_full_state(full, self.now)
            self.pump()

    def of(self, kind: type, side: str = "ctc") -> list:
        return [e for e in getattr(self, f"{side}_events") if isinstance(e, kind)]


def test_ident_request_is_the_worked_example() -> None:
    ixl = IxlSession(20, 0.0)
    assert ixl.data_to_send() == bytes.fromhex("02 06 00 01 00 14 00 01 5B DD")


@pytest.mark.requirement("T2-SESSION-01", "T2-DUMP-01")
def test_ident_accept_then_full_state_in_parts_of_40_in_chart_order() -> None:
    w = Wire()
    state = [(code, code % 3) for code in range(1000, 0, -1)]  # given out of order on purpose
    w.open()
    sent = w.ixl.send_full_state(state, w.now)
    raw = w.ixl.data_to_send()
    parts = frames(raw)
    assert sent == len(parts) == 25
    assert [f.sub for f in parts] == [1] * 24 + [2]
    op = PROFILE.opcodes.by_name["INDICATION"]
    codes = [c for f in parts for c, _ in op.items_of(f.data)]
    assert codes == list(range(1, 1001))
    assert all(len(op.items_of(f.data)) <= 40 for f in parts)
    w.ctc_events += w.ctc.receive_data(raw, w.now)
    (full,) = w.of(ev.FullState)
    assert full.parts == 25 and dict(full.items) == dict(state)
    assert not w.ctc.resync_pending


def test_empty_and_exact_multiple_full_states() -> None:
    w = Wire()
    w.open()
    assert w.ixl.send_full_state([], w.now) == 1
    assert [f.sub for f in frames(w.ixl.data_to_send())] == [2]
    assert w.ixl.send_full_state([(c, 0) for c in range(1, 81)], w.now) == 2
    assert [f.sub for f in frames(w.ixl.data_to_send())] == [1, 2]


@pytest.mark.requirement("T2-ADMIT-01")
def test_ident_refused_closes_both_ends() -> None:
    w = Wire(station=99)
    w.pump()
    w.ctc_events += w.ctc.refuse(w.now, "station 99 is not configured")
    assert w.ctc.closed
    w.pump()
    assert w.of(ev.IdentRefused, "ixl") == [ev.IdentRefused(99)]
    assert w.ixl.closed and "refused" in (w.ixl.close_reason or "")


@pytest.mark.requirement("T2-IND-01")
def test_change_indications_batch_many_codes_per_message() -> None:
    w = Wire()
    w.open(full=[(c, 0) for c in range(1, 101)])
    changes = [(c, 1) for c in range(1, 101)]
    assert w.ixl.send_indications(changes, w.now) == 3
    w.pump()
    got = [i for e in w.of(ev.IndicationsChanged) for i in e.items]
    assert got == changes


def test_indication_change_worked_example() -> None:
    w = Wire()
    w.open()
    w.ixl._tx_seq = 7
    w.ixl.send_indications([(5, 1), (300, 0)], w.now)
    assert w.ixl.data_to_send() == bytes.fromhex("02 09 07 10 00 05 00 01 2C 01 00 3D 5B")


@pytest.mark.requirement("T2-CONTROL-01")
def test_control_and_control_result() -> None:
    w = Wire()
    w.open(full=[])
    w.ctc.send_control([(7, 1), (9, 1)], w.now)
    w.pump()
    (req,) = w.of(ev.ControlRequested, "ixl")
    assert req.items == ((7, 1), (9, 1))
    w.ixl.send_control_result(7, True, 0, w.now)
    w.ixl.send_control_result(9, False, 2, w.now)
    w.pump()
    assert w.of(ev.ControlAnswered) == [
        ev.ControlAnswered(7, True, 0, "none"),
        ev.ControlAnswered(9, False, 2, "route conflicts"),
    ]


@pytest.mark.requirement("T2-DUMP-02")
def test_request_all_is_announced_to_the_ixl() -> None:
    w = Wire()
    w.open(full=[])
    w.ctc.request_all(w.now)
    w.pump()
    assert w.of(ev.FullStateRequested, "ixl") == [ev.FullStateRequested()]


def test_sending_before_ident_is_a_usage_error() -> None:
    w = Wire()
    with pytest.raises(UsageError):
        w.ixl.send_indications([(1, 1)], w.now)
    with pytest.raises(UsageError):
        w.ctc.send_control([(1, 1)], w.now)


@pytest.mark.requirement("T2-HB-01")
def test_heartbeats_keep_an_idle_link_up() -> None:
    w = Wire()
    w.open(full=[])
    sent_before = w.ixl.frames_sent, w.ctc.frames_sent
    w.advance(10.0)
    assert not w.ixl.closed and not w.ctc.closed
    # about one heartbeat a second each way
    assert 9 <= w.ixl.frames_sent - sent_before[0] <= 11
    assert 9 <= w.ctc.frames_sent - sent_before[1] <= 11
    assert w.ixl.next_deadline() is not None


@pytest.mark.requirement("T2-HB-01")
def test_link_down_after_t_max_of_silence() -> None:
    w = Wire()
    w.open(full=[])
    w.advance(2.9, pump=False)  # the wire is cut: nothing delivered
    assert not w.ctc.closed
    w.advance(0.2, pump=False)
    assert w.ctc.closed and w.ixl.closed
    (down,) = w.of(ev.LinkDown)
    assert down.silent_for == pytest.approx(3.0)
    assert "link down" in (w.ctc.close_reason or "")


@example(start=3.35, opened=False)  # 3.35 + 3.0 - 3.35 < 3.0: once stuck at its deadline
@example(start=3.35, opened=True)
@given(start=st.floats(0.0, 1e7), opened=st.booleans())
def test_a_timer_call_at_the_deadline_leaves_no_deadline_at_or_before_it(
    start: float, opened: bool
) -> None:
    w = Wire(start=start)
    if opened:
        w.open(full=[])
    for _ in range(6):  # heartbeats, then (nothing delivered) link down
        for session in (w.ixl, w.ctc):
            due = session.next_deadline()
            if due is not None and due <= w.now + 1.0:
                w.now = max(w.now, due)
                session.handle_timer(w.now)
                after = session.next_deadline()
                assert after is None or after > w.now, (after, w.now)
        w.now += 1.0


def test_no_ident_within_the_timeout_closes() -> None:
    ctc = CtcConnection(0.0)
    ctc.receive_data(CODEC.encode_message(0, "HEARTBEAT", 0), 0.5)
    assert ctc.handle_timer(3.0) == [ev.Closed("no IDENT exchange within 3 s")]


def test_nothing_but_the_ident_answer_before_ident() -> None:
    """The IXL's IDENT is a session's first frame: an unidentified CTC connection sends nothing
    (no HEARTBEAT) until the IDENT timeout closes it."""
    ctc = CtcConnection(0.0)
    now = 0.0
    while not ctc.closed:
        due = ctc.next_deadline()
        assert due is not None
        now = due
        ctc.handle_timer(now)
        assert ctc.data_to_send() == b"", now
    assert now == pytest.approx(3.0)


def test_crc_error_is_naked_and_the_frame_retransmitted_once_delivered() -> None:
    w = Wire()
    w.open(full=[(1, 0), (2, 0)])
    w.ixl.send_indications([(1, 1)], w.now)
    w.ixl.send_indications([(2, 1)], w.now)
    raw = bytearray(w.ixl.data_to_send())
    raw[6] ^= 0x40  # damage the first frame's DATA
    w.ctc_events += w.ctc.receive_data(bytes(raw), w.now)
    assert w.of(ev.IndicationsChanged) == []  # neither acted on
    bad = w.of(ev.BadFrameReceived)[0]  # the decoder may add garbage records for its remains
    assert bad.reason == 1 and bad.nak_sent
    assert [b.nak_sent for b in w.of(ev.BadFrameReceived)[1:]] in ([], [False])
    nak = frames(w.ctc.data_to_send())
    assert [(f.op, f.sub) for f in nak] == [(0x15, 1)]
    w.ixl_events += w.ixl.receive_data(nak[0].raw, w.now)
    (re,) = w.of(ev.Retransmission, "ixl")
    assert re.seq == bad.refused_seq and re.attempt == 1 and re.frames == 2
    w.pump()
    got = [i for e in w.of(ev.IndicationsChanged) for i in e.items]
    assert got == [(1, 1), (2, 1)]  # exactly once, in order


def test_three_retransmissions_then_the_sender_closes() -> None:
    w = Wire()
    w.open(full=[])
    w.ixl.send_indications([(1, 1)], w.now)
    # the original and every retransmission are damaged on the way (heartbeats pass)
    w.damage = lambda raw: raw[:-1] + bytes([raw[-1] ^ 0xFF]) if raw[3] == 0x10 else raw
    w.advance(10.0)
    assert [e.attempt for e in w.of(ev.Retransmission, "ixl")] == [1, 2, 3]
    assert w.ixl.closed and "3 retransmissions" in (w.ixl.close_reason or "")
    assert w.ctc.closed  # it gives up on its own too, a NAK later
    assert w.of(ev.IndicationsChanged) == []


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (CODEC.encode(5, 0x77, b"", 0), 4),  # unknown opcode
        (CODEC.encode(5, 0x10, b"\x01\x00", 0), 3),  # items not a multiple of 3
        (CODEC.encode(5, 0x10, b"", 9), 3),  # unknown sub
        (CODEC.encode(5, 0x20, b"\x01\x00\x01", 0), 4),  # CONTROL is CTC -> IXL only
    ],
)
def test_bad_format_is_never_acted_on(frame: bytes, reason: int) -> None:
    w = Wire()
    w.open(full=[])
    w.ctc._rx_expected = 5
    w.ctc_events += w.ctc.receive_data(frame, w.now)
    (bad,) = w.of(ev.BadFrameReceived)
    assert (bad.reason, bad.refused_seq) == (reason, 5)
    (nak,) = frames(w.ctc.data_to_send())
    assert (nak.op, nak.sub, nak.data) == (0x15, reason, b"\x05")
    assert w.of(ev.IndicationsChanged) == []


def test_stray_bytes_are_naked_and_the_next_frame_still_accepted() -> None:
    w = Wire()
    w.open(full=[])
    w.ctc_events += w.ctc.receive_data(b"\xff\xfe\xfd", w.now)
    w.ixl.send_indications([(4, 1)], w.now)
    w.pump()
    assert w.of(ev.BadFrameReceived)[0].reason == 3
    # the NAK crossed the frame on the wire: the go-back copy is a duplicate and is dropped
    assert len(w.of(ev.Retransmission, "ixl")) == 1
    assert [i for e in w.of(ev.IndicationsChanged) for i in e.items] == [(4, 1)]


def test_a_nak_for_a_frame_not_yet_sent_resends_nothing() -> None:
    w = Wire()
    w.open(full=[])
    w.ctc_events += w.ctc.receive_data(b"\xff\xfe\xfd" + CODEC.encode(0, 0x40, b"", 0), w.now)
    w.pump()
    assert w.of(ev.NakReceived, "ixl") and w.of(ev.Retransmission, "ixl") == []
    w.ixl.send_indications([(4, 1)], w.now)
    w.pump()
    assert [i for e in w.of(ev.IndicationsChanged) for i in e.items] == [(4, 1)]


def test_seq_gap_makes_the_ctc_ask_request_all_and_the_dump_restores_the_view() -> None:
    w = Wire()
    w.open(full=[(c, 0) for c in range(1, 51)])
    w.ixl.send_indications([(3, 1)], w.now)
    w.ixl.data_to_send()  # lost on the way
    w.ixl.send_indications([(4, 1)], w.now)
    w.pump()
    (gap,) = w.of(ev.SequenceGap)
    assert gap.received == (gap.expected + 1) % 256
    assert w.of(ev.FullStateRequested, "ixl") == [ev.FullStateRequested()]
    view = dict(w.of(ev.FullState)[0].items)
    for e in w.of(ev.IndicationsChanged):
        view.update(e.items)
    w.ixl.send_full_state([(c, 1 if c in (3, 4) else 0) for c in range(1, 51)], w.now)
    w.pump()
    assert dict(w.of(ev.FullState)[-1].items) == {c: int(c in (3, 4)) for c in range(1, 51)}


def test_seq_wraps_without_gaps() -> None:
    w = Wire()
    w.open(full=[])
    for k in range(600):
        w.ixl.send_indications([(1, k % 2)], w.now)
        w.pump()
    assert w.of(ev.SequenceGap) == []
    assert len(w.of(ev.IndicationsChanged)) == 600


def test_byte_at_a_time_delivery() -> None:
    w = Wire()
    w.pump()
    w.ctc.accept(w.now)
    w.pump()
    w.ixl.send_full_state([(c, 1) for c in range(1, 100)], w.now)
    for b in w.ixl.data_to_send():
        w.ctc_events += w.ctc.receive_data(bytes([b]), w.now)
    assert len(w.of(ev.FullState)[0].items) == 99
    assert w.of(ev.BadFrameReceived) == []


def test_frames_before_ident_close_the_connection() -> None:
    ctc = CtcConnection(0.0)
    out = ctc.receive_data(CODEC.encode_message(0, "INDICATION", 0, items=[[1, 1]]), 0.1)
    assert ctc.closed and isinstance(out[-1], ev.Closed)


@given(chunks=st.lists(st.binary(max_size=200), max_size=20), valid=st.booleans())
def test_any_bytes_are_survived_by_both_sides(chunks: list[bytes], valid: bool) -> None:
    """Arbitrary input never raises, and the sessions keep answering (or close cleanly)."""
    w = Wire()
    if valid:
        w.open(full=[])
    now = 0.0
    for data in chunks:
        now += 0.1
        w.ctc.receive_data(data, now)
        w.ixl.receive_data(data, now)
        w.ctc.handle_timer(now)
        w.ixl.handle_timer(now)
    for s in (w.ctc, w.ixl):
        s.data_to_send()
        assert s.closed or s.next_deadline() is not None
