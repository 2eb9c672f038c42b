"""Type I cases (SPEC §3): the suite plays the device's peer on its serial endpoint with raw frames.

Every case starts from `settle()` (our LINK_TEST acknowledged, the device quiet) and ends with the
link usable again, so the cases run in any order and any subset.
"""

from __future__ import annotations

import dataclasses
import time

from ktcs_bench import kinds
from ktcs_bench.codec import Frame, FrameCodec
from ktcs_bench.conformance.model import Case, CaseContext
from ktcs_bench.conformance.timing import mean_interval, seconds
from ktcs_bench.conformance.wire import Type1Wire

NAK_CRC, NAK_TIMEOUT, NAK_FORMAT = 1, 2, 3
UNKNOWN_OP = 0x0077  # not in protocols/type1.yaml


def _request_all(
    w: Type1Wire, start: int = 0, count: int | None = None, seq: int | None = None
) -> bytes:
    opcode = w.profile.opcodes.by_name["REQUEST_ALL"]
    values = {f.name: (1 << 8 * f.size) - 1 if f.name == "count" else 0 for f in opcode.fields}
    values["start"] = start
    if count is not None:
        values["count"] = count
    return w.frame("REQUEST_ALL", opcode.build(values), seq)


def _op(w: Type1Wire, f: Frame, name: str) -> bool:
    return f.ok and f.op == w.op[name]


def _ack_window(ctx: CaseContext) -> float:
    return ctx.timing.ack_timeout + ctx.timing.tolerance


def _nak_reason(f: Frame) -> int | None:
    return f.data[0] if f.data else None


def _corrupt_crc(w: Type1Wire, frame: bytes) -> bytes:
    data_len = len(frame) - w.profile.header_size - w.profile.trailer_size
    pos = w.profile.header_size + data_len  # first CRC byte
    bad = bytearray(frame)
    bad[pos] ^= 0x5A
    return bytes(bad)


def _released(ctx: CaseContext, seq: int) -> None:
    """Acknowledge a frame we held back, and go back to acknowledging everything."""
    w = ctx.wire
    w.auto_ack = True
    w.send_raw(w.codec.encode(seq, w.op["ACK"]), f"ACK SEQ 0x{seq:02X} (release)")
    w.collect(0.1)


# -- the cases ------------------------------------------------------------------------------------
def framing(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    seq = w.next_seq()
    w.send_raw(w.codec.encode(seq, w.op["LINK_TEST"]))
    w.send_raw(_request_all(w))
    w.wait_for(lambda f: _op(w, f, "ALL_INFO"), _ack_window(ctx) + 0.3)
    w.collect(0.15)
    got = w.received
    ctx.check(bool(got), f"the device answered within {_ack_window(ctx) + 0.3:.2f} s")
    bad = [f for _, f in got if not f.ok]
    ctx.check(
        not bad,
        "every frame from the device checks (STX, LEN, CRC in the profile's byte order, ETX)"
        + (f"; first bad: {bad[0].error} in {bad[0].raw.hex(' ')}" if bad else ""),
    )
    ctx.check(w.garbage == 0, "no bytes outside frames")
    ctx.check(any(_op(w, f, "ACK") and f.seq == seq for _, f in got),
              f"our LINK_TEST SEQ 0x{seq:02X} is acknowledged with its SEQ")  # fmt: skip
    acks = [f for _, f in got if _op(w, f, "ACK")]
    ctx.check(all(not f.data for f in acks), "ACK frames carry no DATA")


def crc_error_nak(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    seq = w.next_seq()
    good = w.codec.encode(seq, w.op["LINK_TEST"])
    w.send_raw(_corrupt_crc(w, good), f"LINK_TEST SEQ 0x{seq:02X} with a corrupted CRC byte")
    nak = w.wait_for(w.nak(), _ack_window(ctx))
    ctx.check(nak is not None, "a frame with a CRC error is answered with NAK")
    assert nak is not None
    ctx.check(_nak_reason(nak[1]) == NAK_CRC, f"NAK reason is 1 (CRC), got {_nak_reason(nak[1])}")
    w.collect(0.1)
    ctx.check(not any(_op(w, f, "ACK") and f.seq == seq for _, f in w.received),
              "the corrupted frame is not acknowledged")  # fmt: skip
    w.send_raw(good, f"LINK_TEST SEQ 0x{seq:02X} again, intact")
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx)) is not None,
              "the same frame sent intact is acknowledged")  # fmt: skip


def _time_delta_r(ctx: CaseContext, limit: float) -> tuple[float, Frame] | None:
    """Send the first 4 bytes of a frame, then keep silent -- no ACK of the device's LINK_TEST
    either, which it would read as the rest of our frame -- until its NAK (at most `limit` s).
    Returns (seconds from our last byte to the NAK, the NAK)."""
    w = ctx.wire
    w.settle()
    seq = w.next_seq()
    frame = w.codec.encode(seq, w.op["LINK_TEST"])
    t0 = w.send_raw(frame[:4], "first 4 bytes of a LINK_TEST, then silence")
    with w.silent("the device times ΔR on our incomplete frame"):
        nak = w.wait_for(w.nak(), limit)
    if nak is None:
        return None
    if _nak_reason(nak[1]) == NAK_TIMEOUT:
        ctx.measured.delta_r = nak[0] - t0
    return nak[0] - t0, nak[1]


def delta_r_nak(ctx: CaseContext) -> None:
    t = ctx.timing
    got = _time_delta_r(ctx, t.delta_r + t.tolerance + 0.2)
    ctx.check(got is not None, f"an incomplete frame is answered with NAK (ΔR = {t.delta_r:.3f} s)")
    assert got is not None
    waited, nak = got
    ctx.check(_nak_reason(nak) == NAK_TIMEOUT,
              f"NAK reason is 2 (frame timeout ΔR), got {_nak_reason(nak)}")  # fmt: skip
    ctx.check(t.within(waited, t.delta_r),
              f"NAK after {waited * 1000:.0f} ms: within ΔR {t.delta_r * 1000:.0f} ms "
              f"(-20 %, +{t.tolerance * 1000:.0f} ms)")  # fmt: skip
    ctx.wire.settle()


def _hold_one(ctx: CaseContext) -> tuple[float, Frame]:
    """Stop acknowledging, make the device send a data frame, return it."""
    w = ctx.wire
    w.settle()
    w.auto_ack = False
    w.send_raw(_request_all(w))
    first = w.wait_for(w.is_data, _ack_window(ctx) + 0.5)
    ctx.check(first is not None, "the device answers REQUEST_ALL with a data frame")
    assert first is not None
    ctx.note(f"holding back the ACK of {w.name_of(first[1])} SEQ 0x{first[1].seq:02X}")
    return first


def _transmissions(ctx: CaseContext, held: tuple[float, Frame], first: float,
                   then: float | None, most: int) -> list[tuple[float, Frame]]:  # fmt: skip
    """Keep silent while the device retransmits the frame we hold back: its transmissions (the
    first included) with their times, waiting `first` s for the first retransmission and `then` s
    for each next one (None: twice the first interval + tolerance), at most `most` of them."""
    w = ctx.wire
    t1, frame = held
    seen = [held]
    wait = first
    with w.silent(f"the device times its ACK timeout on SEQ 0x{frame.seq:02X}"):
        while len(seen) <= most:
            got = w.wait_for(lambda f: w.is_data(f) and f.seq == frame.seq, wait)
            if got is None:
                break
            seen.append(got)
            wait = then if then is not None else 2 * (seen[1][0] - t1) + ctx.timing.tolerance
    if len(seen) > 1:
        ctx.measured.ack_timeout = seen[1][0] - t1 - ctx.timing.wire_time(len(frame.raw))
    return seen


def ack_timeout_retransmission(ctx: CaseContext) -> None:
    t = ctx.timing
    held = _hold_one(ctx)
    t1, first = held
    nominal = t.ack_timeout + t.wire_time(len(first.raw))
    sent = _transmissions(ctx, held, nominal + t.tolerance, None, 1)
    assert first.seq is not None
    ctx.check(len(sent) > 1, "without an ACK the device retransmits the frame with the same SEQ")
    at, again = sent[1]
    ctx.check(again.raw == first.raw, "the retransmission is byte for byte the same frame")
    ctx.check(t.within(at - t1, nominal),
              f"retransmitted after {(at - t1) * 1000:.0f} ms: the ACK timeout "
              f"{t.ack_timeout * 1000:.0f} ms + wire time")  # fmt: skip
    _released(ctx, first.seq)


def _recover(ctx: CaseContext) -> bool:
    """After a communication error: our next frame brings the link up, and the device asks for the
    full state (SPEC §3.4: on recovery each side sends REQUEST_ALL). Did it?"""
    w = ctx.wire
    w.auto_ack = True
    seq = w.next_seq()
    mark = len(w.received)
    w.send_raw(w.codec.encode(seq, w.op["LINK_TEST"]), f"LINK_TEST SEQ 0x{seq:02X} (recovery)")
    req = w.wait_for(lambda f: _op(w, f, "REQUEST_ALL"), 2 * _ack_window(ctx) + 1.5, mark)
    return req is not None


def retry_limit(ctx: CaseContext) -> None:
    t = ctx.timing
    held = _hold_one(ctx)
    first = held[1]
    assert first.seq is not None
    quiet = t.ack_timeout + t.wire_time(len(first.raw)) + t.tolerance + 0.3
    sent = _transmissions(ctx, held, quiet, quiet, t.retry_count + 3)
    ctx.measured.retry_count = len(sent) - 1
    ctx.check(len(sent) == t.retry_count + 1,
              f"{len(sent)} transmissions of SEQ 0x{first.seq:02X}: exactly "
              f"{t.retry_count + 1} (1 + {t.retry_count} retransmissions) then communication error")  # fmt: skip
    ctx.check(_recover(ctx), "after the communication error the device rebuilds: REQUEST_ALL")
    ctx.wire.settle()


def nak_retransmission(ctx: CaseContext) -> None:
    w, t = ctx.wire, ctx.timing
    _, first = _hold_one(ctx)
    assert first.seq is not None
    w.send_raw(w.codec.encode(first.seq, w.op["NAK"], bytes([NAK_CRC])),
               f"NAK reason 1 for SEQ 0x{first.seq:02X}")  # fmt: skip
    again = w.wait_for(lambda f: w.is_data(f) and f.seq == first.seq, t.ack_timeout + t.tolerance)
    ctx.check(again is not None, "after our NAK the device retransmits the frame, same SEQ")
    assert again is not None
    ctx.check(again[1].raw == first.raw, "the retransmission is byte for byte the same frame")
    _released(ctx, first.seq)


def duplicate_seq(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    seq = w.next_seq()
    frame = _request_all(w, seq=seq)
    start = len(w.received)
    w.send_raw(frame)
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx), start) is not None,
              "REQUEST_ALL acknowledged")  # fmt: skip
    info = w.wait_for(lambda f: _op(w, f, "ALL_INFO"), _ack_window(ctx) + 0.5, start)
    ctx.check(info is not None, "REQUEST_ALL answered with ALL_INFO")
    w.collect(0.3)
    seen = {f.seq for _, f in w.received if _op(w, f, "ALL_INFO")}
    mark = len(w.received)
    w.send_raw(frame, f"the same REQUEST_ALL again, SEQ 0x{seq:02X} repeated")
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx), mark) is not None,
              "the repeated SEQ is acknowledged again")  # fmt: skip
    w.collect(_ack_window(ctx) + 0.3)
    again = [f for _, f in w.received[mark:] if _op(w, f, "ALL_INFO") and f.seq not in seen]
    ctx.check(not again, "the repeat is not delivered twice: no second ALL_INFO answers it")


def resync_after_garbage(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    stx = w.profile.stx
    # noise, a false STX announcing a long frame, a false STX with a short LEN, more noise
    junk = bytes([0x55, 0xAA, stx, 0xFF, 0x03, 0x10, stx, 0x02, 0x00, 0x07, 0x11, 0xFE])
    seq = w.next_seq()
    w.send_raw(junk + w.codec.encode(seq, w.op["LINK_TEST"]),
               f"12 bytes of garbage with false STX, then LINK_TEST SEQ 0x{seq:02X}")  # fmt: skip
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx) + 0.3) is not None,
              "the valid frame behind the garbage is found and acknowledged")  # fmt: skip
    w.send_raw(b"\xff\x00\x13\x37" * 8, "32 bytes of noise without STX")
    seq = w.next_seq()
    w.send_raw(w.codec.encode(seq, w.op["LINK_TEST"]))
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx) + 0.3) is not None,
              "after noise the next valid frame is acknowledged")  # fmt: skip
    w.collect(0.2)


def request_all(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    w.send_raw(_request_all(w))
    got = w.wait_for(lambda f: _op(w, f, "ALL_INFO"), _ack_window(ctx) + 0.5)
    ctx.check(got is not None, "REQUEST_ALL (start 0, count all) is answered with ALL_INFO")
    assert got is not None
    full = got[1].data
    if ctx.codes is not None:
        ctx.check(len(full) == ctx.codes,
                  f"ALL_INFO carries {len(full)} statuses: the chart's {ctx.codes} codes")  # fmt: skip
    else:
        ctx.note(f"ALL_INFO carries {len(full)} statuses (chart size not given)")
    w.collect(0.2)
    if len(full) >= 3:
        w.send_raw(_request_all(w, start=1, count=2))
        part = w.wait_for(lambda f: _op(w, f, "ALL_INFO"), _ack_window(ctx) + 0.5)
        ctx.check(part is not None and part[1].data == full[1:3],
                  "REQUEST_ALL start 1 count 2 gives statuses of codes 2 and 3")  # fmt: skip
        w.collect(0.2)
    w.send_raw(_request_all(w, start=0, count=len(full) + 50))
    clipped = w.wait_for(lambda f: _op(w, f, "ALL_INFO"), _ack_window(ctx) + 0.5)
    ctx.check(clipped is not None and clipped[1].data == full,
              "a count past the end of the chart is clipped, not refused")  # fmt: skip
    w.collect(0.2)


def maximum_length(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    p = w.profile
    # Statuses that are the restrictive side for the receiver: "occupied" for an IXL, else 0.
    fill = 1 if ctx.role == kinds.IXL else 0
    seq = w.next_seq()
    w.send_raw(w.frame("ALL_INFO", bytes([fill]) * p.max_data, seq),
               f"ALL_INFO SEQ 0x{seq:02X} with LEN = the maximum {p.max_data}")  # fmt: skip
    ctx.check(w.wait_for(w.ack_of(seq), _ack_window(ctx) + 0.5) is not None,
              f"a frame of the maximum length ({p.max_data} DATA bytes) is accepted")  # fmt: skip
    longer = FrameCodec(dataclasses.replace(p, max_len=p.max_len + 1))
    seq = w.next_seq()
    w.send_raw(longer.encode(seq, w.op["ALL_INFO"], bytes([fill]) * (p.max_data + 1)),
               f"ALL_INFO SEQ 0x{seq:02X} with LEN {p.max_len + 1}, one past the maximum")  # fmt: skip
    nak = w.wait_for(w.nak(), _ack_window(ctx) + 0.5)
    ctx.check(nak is not None and _nak_reason(nak[1]) == NAK_FORMAT,
              "a frame longer than the maximum is refused with NAK reason 3 (length)")  # fmt: skip
    w.collect(0.2)
    ctx.check(not any(_op(w, f, "ACK") and f.seq == seq for _, f in w.received),
              "the over-long frame is not acknowledged")  # fmt: skip
    w.settle()


def unknown_opcode(ctx: CaseContext) -> None:
    w = ctx.wire
    w.settle()
    seq = w.next_seq()
    w.send_raw(w.frame(UNKNOWN_OP, b"\x01\x02", seq),
               f"opcode 0x{UNKNOWN_OP:04X} (not in the profile), SEQ 0x{seq:02X}")  # fmt: skip
    nak = w.wait_for(w.nak(), _ack_window(ctx))
    ctx.check(nak is not None, "an unknown opcode is answered with NAK")
    assert nak is not None
    ctx.check(_nak_reason(nak[1]) == NAK_FORMAT,
              f"NAK reason is 3 (format), got {_nak_reason(nak[1])}")  # fmt: skip
    w.collect(0.1)
    ctx.check(not any(_op(w, f, "ACK") and f.seq == seq for _, f in w.received),
              "the unknown opcode is not acknowledged")  # fmt: skip


def _link_tests(ctx: CaseContext, count: int, limit: float) -> list[float]:
    """Keep the link idle (only ACKs from us) and return the arrival times of the device's next
    `count` LINK_TESTs, waiting at most `limit` s for all of them."""
    w = ctx.wire
    w.settle()
    end = time.monotonic() + limit
    tests: list[float] = []
    seen: set[int] = set()
    with w.silent("the idle device times its link-test period", acks=True):
        while time.monotonic() < end and len(tests) < count:
            got = w.wait_for(lambda f: _op(w, f, "LINK_TEST") and f.seq not in seen,
                             end - time.monotonic())  # fmt: skip
            if got is None:
                break
            assert got[1].seq is not None
            seen.add(got[1].seq)
            tests.append(got[0])
    ctx.measured.link_test_period = mean_interval(tests) or ctx.measured.link_test_period
    return tests


def link_test_timing(ctx: CaseContext) -> None:
    t = ctx.timing
    limit = 2 * t.link_test_period + t.tolerance + 0.5
    tests = _link_tests(ctx, 2, limit)
    ctx.check_period("LINK_TEST", tests, t.link_test_period, limit, "link-test period")


def measure(ctx: CaseContext, limit: float) -> None:
    """`--timings auto`: measure the link-test period, ΔR, the ACK timeout and the retry count,
    waiting at most `limit` s for any one timer; the figures land in `ctx.measured`."""
    m = ctx.measured
    _link_tests(ctx, 3, 3 * limit)
    ctx.note(f"link-test period: {seconds(m.link_test_period)}")
    _time_delta_r(ctx, limit)
    ctx.note(f"ΔR: {seconds(m.delta_r)}")
    ctx.wire.settle()
    sent = _transmissions(ctx, _hold_one(ctx), limit, None, 16)
    if len(sent) > 1:
        m.retry_count = len(sent) - 1
    ctx.note(f"ACK timeout: {seconds(m.ack_timeout)}; retry count: {m.retry_count}")
    _recover(ctx)
    ctx.wire.settle()


TYPE1_CASES: tuple[Case, ...] = (
    Case("framing", "type1", "frames from the device check: STX, LEN, CRC, ETX; ACK of our frame",
         "§3.1", framing,
         verifies=("T1-FRAME-01", "T1-CRC-01", "T1-ARQ-01")),
    Case("crc-error-nak", "type1", "a CRC error is answered with NAK reason 1, never ACKed",
         "§3.4 ①", crc_error_nak,
         verifies=("T1-CRC-02", "T1-CRC-01")),
    Case("delta-r-nak", "type1", "an incomplete frame is answered with NAK reason 2 after ΔR",
         "§3.4 ②", delta_r_nak,
         verifies=("T1-DR-01",)),
    Case("ack-timeout-retransmission", "type1",
         "no ACK within the ACK timeout: retransmission with the same SEQ", "§3.4 ③",
         ack_timeout_retransmission,
         verifies=("T1-ARQ-02",)),
    Case("retry-limit", "type1",
         "exactly 3 retransmissions, then communication error and REQUEST_ALL on recovery",
         "§3.4", retry_limit,
         verifies=("T1-ARQ-03", "T1-RESYNC-01")),
    Case("nak-retransmission", "type1", "a NAK makes the device retransmit the same frame",
         "§3.4 ①", nak_retransmission,
         verifies=("T1-CRC-02",)),
    Case("duplicate-seq", "type1", "a repeated SEQ is acknowledged again but not delivered twice",
         "§3.4", duplicate_seq,
         verifies=("T1-ARQ-04",)),
    Case("resync-after-garbage", "type1", "after garbage and false STX the next frame is found",
         "§3.1", resync_after_garbage,
         verifies=("T1-FRAME-03",)),
    Case("request-all", "type1", "REQUEST_ALL is answered with ALL_INFO of the chart's size",
         "§3.3, §3.5", request_all,
         verifies=("T1-CODES-01",)),
    Case("maximum-length", "type1", "LEN = maximum accepted; one more refused with NAK reason 3",
         "§3.1", maximum_length,
         verifies=("T1-FRAME-02",)),
    Case("unknown-opcode", "type1", "an unknown opcode is answered with NAK reason 3",
         "§3.3", unknown_opcode,
         verifies=("T1-FRAME-04",)),
    Case("link-test-timing", "type1", "an idle device sends LINK_TEST every link-test period",
         "§3.3, §3.4", link_test_timing,
         verifies=("T1-LINK-01",)),
)  # fmt: skip
