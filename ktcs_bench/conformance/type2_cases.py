"""Type II cases (SPEC §4, §10): the suite plays the CTC (against an IXL, `--role ixl --target
listen://…`) or an IXL (against a CTC, `--role ctc --target tcp://…`), one connection per case.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

from ktcs_bench import kinds
from ktcs_bench.codec import Frame, FrameCodec
from ktcs_bench.conformance.model import Case, CaseContext, NotApplicable
from ktcs_bench.conformance.timing import mean_interval, seconds
from ktcs_bench.conformance.wire import Type2Wire

NAK_CRC, NAK_FORMAT, NAK_UNKNOWN = 1, 3, 4
MAX_ITEMS = 40
UNKNOWN_OP = 0x77
UNKNOWN_STATION = 65000
UNKNOWN_CONTROL = 0xFFFF
IDENT_WAIT = 3.0  # the IXL sends IDENT first, at once; the CTC answers at once


def _is(w: Type2Wire, f: Frame, name: str, sub: int | None = None) -> bool:
    return f.ok and f.op == w.op[name] and (sub is None or f.sub == sub)


def _kind(w: Type2Wire, name: str, sub: int | None = None) -> Callable[[Frame], bool]:
    return lambda f: _is(w, f, name, sub)


def _items(w: Type2Wire, f: Frame) -> list[list[int]]:
    return w.profile.opcodes.by_name["INDICATION"].items_of(f.data)


def _station(ctx: CaseContext) -> int:
    if ctx.station is None:
        raise NotApplicable("needs --station")
    return ctx.station


def _window(ctx: CaseContext) -> float:
    return 1.0 + ctx.timing.tolerance


def _read_dump(ctx: CaseContext, w: Type2Wire, since: int = 0) -> list[Frame]:
    """INDICATION full-state parts (received from index `since` on) until the last one (sub 2)."""
    parts: list[Frame] = []
    end = time.monotonic() + 5.0 + ctx.timing.tolerance
    i = since
    while time.monotonic() < end and not w.closed:
        while i < len(w.received):
            f = w.received[i][1]
            i += 1
            if _is(w, f, "INDICATION") and f.sub in (1, 2):
                parts.append(f)
                if f.sub == 2:
                    return parts
        w.poll(0.05)
    ctx.check(False, f"a complete full state (last part sub 2) within 5 s; {len(parts)} parts seen")
    return parts


def _check_dump(ctx: CaseContext, w: Type2Wire, parts: list[Frame]) -> None:
    sizes = [len(_items(w, f)) for f in parts]
    ctx.check(all(n <= MAX_ITEMS for n in sizes), f"every part carries <= 40 items ({sizes})")
    ctx.check(all(f.sub == 1 for f in parts[:-1]) and parts[-1].sub == 2,
              "parts are sub 1 (full-state part) and the last sub 2")  # fmt: skip
    codes = [c for f in parts for c, _ in _items(w, f)]
    ordered = all(a < b for a, b in zip(codes, codes[1:], strict=False))
    first_bad = next(
        (i for i, (a, b) in enumerate(zip(codes, codes[1:], strict=False)) if a >= b), None
    )
    ctx.check(ordered, "codes come in chart order, each once"
              + ("" if first_bad is None else f" (code {codes[first_bad + 1]} after {codes[first_bad]})"))  # fmt: skip
    if ctx.codes is not None:
        ctx.check(len(codes) == ctx.codes and codes == list(range(1, ctx.codes + 1)),
                  f"the dump holds every code of the chart: {len(codes)} of {ctx.codes}")  # fmt: skip
    else:
        ctx.note(f"the dump holds {len(codes)} codes (chart size not given)")


def _open(ctx: CaseContext, accept: bool = True) -> tuple[Type2Wire, Frame | None]:
    """A connection with the IDENT exchange done: the suite as CTC answers the IXL's IDENT; the
    suite as IXL sends its own. Returns the device's IDENT frame."""
    if ctx.role == kinds.CTC:
        w = ctx.connect()
        st = _station(ctx)
        w.send_raw(w.message("IDENT", 0, station=st, version=1))
        got = w.wait_for(lambda f: _is(w, f, "IDENT"), IDENT_WAIT)
        if got is not None and got[1].sub == 1 and accept:
            _send_dump(ctx, w)
        return w, got[1] if got else None
    for _ in range(3):
        w = ctx.connect()
        got = w.wait_for(_kind(w, "IDENT"), IDENT_WAIT + ctx.timing.tolerance)
        if got is None and w.closed:
            continue  # a stale connection from the backlog: take the next
        if got is not None:
            f = got[1]
            station = w.profile.opcodes.by_name["IDENT"].parse(f.data)["station"]
            w.send_raw(w.message("IDENT", 1 if accept else 2, station=station, version=1))
        return w, got[1] if got else None
    return w, None


def _send_dump(ctx: CaseContext, w: Type2Wire, codes: int | None = None) -> None:
    n = codes if codes is not None else (ctx.codes or 1)
    items = [[c, 0] for c in range(1, n + 1)]
    op = w.profile.opcodes.by_name["INDICATION"]
    chunks = [items[k : k + MAX_ITEMS] for k in range(0, len(items), MAX_ITEMS)]
    for i, chunk in enumerate(chunks):
        w.send_raw(w.frame("INDICATION", 2 if i == len(chunks) - 1 else 1, op.pack_items(chunk)))


def _opened(ctx: CaseContext) -> Type2Wire:
    w, ident = _open(ctx)
    ctx.check(ident is not None and ident.sub in (0, 1), "IDENT exchange")
    if ctx.role == kinds.IXL:
        _read_dump(ctx, w)
    return w


def _no_nak(w: Type2Wire, seconds: float) -> bool:
    mark = len(w.received)
    w.collect(seconds)
    return not any(_is(w, f, "NAK") for _, f in w.received[mark:])


# -- the cases ------------------------------------------------------------------------------------
def ident(ctx: CaseContext) -> None:
    w, f = _open(ctx)
    ctx.check(f is not None, "the device sends/answers IDENT within 3 s")
    assert f is not None
    fields = w.profile.opcodes.by_name["IDENT"].parse(f.data)
    if ctx.role == kinds.CTC:
        ctx.check(f.sub == 1, f"IDENT of configured station {ctx.station} is accepted (sub 1)")
        ctx.check(fields["station"] == ctx.station, "the answer names our station")
    else:
        ctx.check(f.sub == 0, "the IXL's first frame is IDENT request (sub 0)")
        if ctx.station is not None:
            ctx.check(fields["station"] == ctx.station,
                      f"IDENT names station {fields['station']} (expected {ctx.station})")  # fmt: skip
    ctx.check(fields["version"] == 1, f"protocol version {fields['version']} is 1")


def full_dump(ctx: CaseContext) -> None:
    if ctx.role == kinds.CTC:
        w = _opened(ctx)
        ctx.check(_no_nak(w, 0.5), "our full state in parts of 40 is taken without NAK")
        return
    w, f = _open(ctx)
    ctx.check(f is not None, "IDENT exchange")
    _check_dump(ctx, w, _read_dump(ctx, w))


def request_all(ctx: CaseContext) -> None:
    if ctx.role == kinds.CTC:
        raise NotApplicable("the CTC sends REQUEST_ALL; see seq-gap")
    w = _opened(ctx)
    w.collect(0.1)
    mark = len(w.received)
    w.send_raw(w.frame("REQUEST_ALL"))
    _check_dump(ctx, w, _read_dump(ctx, w, mark))


def seq_gap(ctx: CaseContext) -> None:
    if ctx.role != kinds.CTC:
        raise NotApplicable("only the CTC asks REQUEST_ALL on a SEQ gap (the IXL only reports it)")
    w = _opened(ctx)
    w.collect(0.2)
    w.seq = (w.seq + 1) % 256
    op = w.profile.opcodes.by_name["INDICATION"]
    w.send_raw(w.frame("INDICATION", 0, op.pack_items([[1, 0]])), "INDICATION, one SEQ skipped")
    got = w.wait_for(lambda f: _is(w, f, "REQUEST_ALL"), _window(ctx))
    ctx.check(got is not None, "a SEQ gap is answered with REQUEST_ALL")
    _send_dump(ctx, w)
    ctx.check(_no_nak(w, 0.3), "the full state that follows is taken")


def crc_error_nak(ctx: CaseContext) -> None:
    w = _opened(ctx)
    seq = w.seq
    good = w.frame("HEARTBEAT", 0, b"", seq)
    bad = bytearray(good)
    bad[-2] ^= 0x5A
    w.send_raw(bytes(bad), f"HEARTBEAT SEQ 0x{seq:02X} with a corrupted CRC")
    nak = w.wait_for(lambda f: _is(w, f, "NAK"), _window(ctx))
    ctx.check(nak is not None, "a frame with a CRC error is answered with NAK")
    assert nak is not None
    ctx.check(nak[1].sub == NAK_CRC, f"NAK reason (sub) is 1 (CRC), got {nak[1].sub}")
    ctx.check(nak[1].data[:1] == bytes([seq]), f"the NAK names the refused SEQ 0x{seq:02X}")
    w.seq = (seq + 1) % 256
    w.send_raw(good, f"HEARTBEAT SEQ 0x{seq:02X} again, intact")
    ctx.check(_no_nak(w, 0.5), "the intact frame is taken (no further NAK)")


def _refused(ctx: CaseContext, raw: bytes, what: str, reason: int, seq: int) -> None:
    w = ctx.opened[-1]
    w.send_raw(raw, what)
    nak = w.wait_for(lambda f: _is(w, f, "NAK"), _window(ctx))
    ctx.check(nak is not None and nak[1].sub == reason,
              f"{what}: refused with NAK reason {reason}"
              + ("" if nak is None else f" (got {nak[1].sub})"))  # fmt: skip
    # The receiver now waits for that SEQ again: give it a good frame with it.
    w.send_raw(w.frame("HEARTBEAT", 0, b"", seq), f"HEARTBEAT SEQ 0x{seq:02X} in its place")
    ctx.check(_no_nak(w, 0.4), "the link carries on after the refusal")


def unknown_opcode(ctx: CaseContext) -> None:
    w = _opened(ctx)
    seq = w.seq
    w.seq = (seq + 1) % 256
    _refused(ctx, w.frame(UNKNOWN_OP, 0, b"", seq), f"opcode 0x{UNKNOWN_OP:02X}", NAK_UNKNOWN, seq)


def maximum_length(ctx: CaseContext) -> None:
    w = _opened(ctx)
    p = w.profile
    seq = w.seq
    w.seq = (seq + 1) % 256
    longer = FrameCodec(dataclasses.replace(p, max_len=p.max_len + 1))
    raw = longer.encode(seq, w.op["HEARTBEAT"], bytes(p.max_data + 1), 0)
    _refused(ctx, raw, f"LENGTH {p.max_len + 1}, one past the maximum", NAK_FORMAT, seq)
    w.collect(0.2)
    if ctx.role == kinds.CTC:
        op = p.opcodes.by_name["INDICATION"]
        w.send_raw(w.frame("INDICATION", 0, op.pack_items([[c, 0] for c in range(1, 41)])),
                   "INDICATION change with 40 items (LENGTH 123)")  # fmt: skip
        ctx.check(_no_nak(w, 0.5), "a message of the maximum 40 items is taken")
        return
    op = p.opcodes.by_name["CONTROL"]
    mark = len(w.received)
    w.send_raw(w.frame("CONTROL", 0, op.pack_items([[UNKNOWN_CONTROL, 1]] * MAX_ITEMS)),
               f"CONTROL with 40 items (LENGTH 123), code {UNKNOWN_CONTROL}")  # fmt: skip
    end = time.monotonic() + _window(ctx) + 1.0
    while time.monotonic() < end:
        results = [f for _, f in w.received[mark:] if _is(w, f, "CONTROL_RESULT")]
        if len(results) >= MAX_ITEMS:
            break
        w.poll(0.05)
    ctx.check(not any(_is(w, f, "NAK") for _, f in w.received[mark:]),
              "a message of the maximum 40 items is not refused")  # fmt: skip
    ctx.check(len(results) == MAX_ITEMS, f"each of its 40 controls is answered ({len(results)})")


def nak_retransmission(ctx: CaseContext) -> None:
    w = _opened(ctx)
    got = w.wait_for(lambda f: f.ok and not _is(w, f, "NAK"), 2.0 + ctx.timing.tolerance)
    if got is None and w.received:
        got = w.received[-1]
    ctx.check(got is not None, "the device sends a frame to refuse")
    assert got is not None and got[1].seq is not None
    s = got[1].seq
    mark = len(w.received)
    w.send_raw(w.frame("NAK", NAK_CRC, bytes([s])), f"NAK reason 1 for the device's SEQ 0x{s:02X}")
    again = w.wait_for(lambda f: f.ok and f.seq == s, _window(ctx))
    ctx.check(again is not None, f"the device retransmits SEQ 0x{s:02X} after our NAK")
    assert again is not None
    ctx.check(again[1].raw == got[1].raw, "the retransmission is byte for byte the same frame")
    del mark


def _heartbeats(ctx: CaseContext, count: int, limit: float) -> list[float]:
    """On a fresh connection, keep the device's peer alive with our own HEARTBEAT every half
    period and return the arrival times of the device's next `count` HEARTBEATs (at most `limit`
    s)."""
    w = _opened(ctx)
    period = ctx.timing.heartbeat_period
    w.collect(0.1)
    mark = len(w.received)
    end = time.monotonic() + limit
    next_ours = time.monotonic() + period / 2
    beats: list[float] = []
    while time.monotonic() < end and not w.closed and len(beats) < count:
        if time.monotonic() >= next_ours:
            w.send_raw(w.frame("HEARTBEAT"))
            next_ours += period / 2
        w.poll(0.05)
        beats = [at for at, f in w.received[mark:] if _is(w, f, "HEARTBEAT")]
    ctx.measured.heartbeat_period = mean_interval(beats) or ctx.measured.heartbeat_period
    return beats


def heartbeat(ctx: CaseContext) -> None:
    t = ctx.timing
    limit = 2 * t.heartbeat_period + t.tolerance + 0.5
    beats = _heartbeats(ctx, 3, limit)
    ctx.check_period("HEARTBEAT", beats, t.heartbeat_period, limit, "heartbeat period")


def _time_t_max(ctx: CaseContext, limit: float) -> float | None:
    """On a fresh connection, send nothing more and return how long after our last frame the
    device closed it (None: not within `limit` s)."""
    w = _opened(ctx)
    last = w.evidence.records[-1].time + w.evidence.start
    for rec in reversed(w.evidence.records):
        if rec.direction.startswith("suite"):
            last = rec.time + w.evidence.start
            break
    with w.silent("the device times T_MAX on our silence"):
        closed = w.wait_closed(limit)
    if closed is None:
        return None
    ctx.measured.t2_t_max = closed - last
    return closed - last


def t_max(ctx: CaseContext) -> None:
    t = ctx.timing
    waited = _time_t_max(ctx, t.t2_t_max + t.tolerance + 0.5)
    ctx.check(
        waited is not None, f"the device closes the silent connection (T_MAX {t.t2_t_max:.3g} s)"
    )
    assert waited is not None
    ctx.check(t.within(waited, t.t2_t_max),
              f"closed {waited:.2f} s after our last frame: T_MAX {t.t2_t_max:.3g} s")  # fmt: skip


def measure(ctx: CaseContext, limit: float) -> None:
    """`--timings auto`: measure the heartbeat period and T_MAX, waiting at most `limit` s for
    either; the figures land in `ctx.measured`."""
    m = ctx.measured
    _heartbeats(ctx, 3, 2 * limit)
    ctx.note(f"heartbeat period: {seconds(m.heartbeat_period)}")
    for w in ctx.opened:  # one connection at a time: a CTC refuses a second for the station
        w.close()
    _time_t_max(ctx, limit)
    ctx.note(f"T_MAX: {seconds(m.t2_t_max)}")


def refused_station(ctx: CaseContext) -> None:
    if ctx.role == kinds.CTC:
        w = ctx.connect()
        w.send_raw(w.message("IDENT", 0, station=UNKNOWN_STATION, version=1),
                   f"IDENT station {UNKNOWN_STATION} (not configured)")  # fmt: skip
        got = w.wait_for(lambda f: _is(w, f, "IDENT"), IDENT_WAIT)
        ctx.check(got is not None and got[1].sub == 2,
                  "an unknown station is refused (IDENT sub 2)")  # fmt: skip
        ctx.check(w.wait_closed(1.0 + ctx.timing.tolerance) is not None,
                  "and the connection is closed")  # fmt: skip
        return
    w, f = _open(ctx, accept=False)
    ctx.check(f is not None, "the IXL sends IDENT")
    mark = len(w.received)
    closed = w.wait_closed(1.0 + ctx.timing.tolerance)
    sent = [g for _, g in w.received[mark:] if _is(w, g, "INDICATION")]
    ctx.check(not sent, "a refused IXL sends no indications")
    ctx.check(closed is not None, "a refused IXL closes its connection")


def second_connection(ctx: CaseContext) -> None:
    if ctx.role != kinds.CTC:
        raise NotApplicable("the CTC decides who may connect")
    _opened(ctx)
    w2 = ctx.connect()
    st = _station(ctx)
    w2.send_raw(w2.message("IDENT", 0, station=st, version=1),
                f"a second connection claiming station {st}")  # fmt: skip
    got = w2.wait_for(lambda f: _is(w2, f, "IDENT"), IDENT_WAIT)
    ctx.check(got is not None and got[1].sub == 2,
              "a second connection for a connected station is refused (IDENT sub 2)")  # fmt: skip


T2 = (kinds.IXL, kinds.CTC)
TYPE2_CASES: tuple[Case, ...] = (
    Case("t2-ident", "type2", "IDENT exchange: station, version 1", "§4", ident, T2,
         verifies=("T2-SESSION-01", "T2-FRAME-01")),
    Case("t2-full-dump", "type2", "full state after IDENT: <= 40 items a part, chart order, sub 2 last",
         "§4", full_dump, T2,
         verifies=("T2-DUMP-01",)),
    Case("t2-request-all", "type2", "REQUEST_ALL is answered with a complete full state", "§4",
         request_all, (kinds.IXL,),
         verifies=("T2-DUMP-02",)),
    Case("t2-seq-gap", "type2", "a SEQ gap is answered with REQUEST_ALL", "§4", seq_gap, (kinds.CTC,),
         verifies=("T2-DUMP-02",)),
    Case("t2-crc-error-nak", "type2", "a CRC error is answered with NAK 1 naming the SEQ", "§4",
         crc_error_nak, T2,
         verifies=("T2-FRAME-02",)),
    Case("t2-unknown-opcode", "type2", "an unknown opcode is answered with NAK 4", "§4",
         unknown_opcode, T2,
         verifies=("T2-FRAME-04",)),
    Case("t2-maximum-length", "type2", "40 items accepted; LENGTH 125 refused with NAK 3", "§4",
         maximum_length, T2,
         verifies=("T2-FRAME-01", "T2-FRAME-02")),
    Case("t2-nak-retransmission", "type2", "a NAK makes the device resend that SEQ unchanged",
         "§4", nak_retransmission, T2,
         verifies=("T2-FRAME-03",)),
    Case("t2-heartbeat", "type2", "an idle device sends HEARTBEAT every heartbeat period", "§4",
         heartbeat, T2,
         verifies=("T2-HB-01",)),
    Case("t2-t-max", "type2", "a silent peer is dropped after T_MAX", "§4", t_max, T2,
         verifies=("T2-HB-01",)),
    Case("t2-refused-station", "type2", "refusal of an unknown station (IDENT sub 2, close)",
         "§4, §10", refused_station, T2,
         verifies=("T2-ADMIT-01",)),
    Case("t2-second-connection", "type2", "a second connection for one station is refused",
         "§4, §10", second_connection, (kinds.CTC,),
         verifies=("T2-ADMIT-02",)),
)  # fmt: skip
