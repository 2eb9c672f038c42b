"""The streaming decoder: any chunking, resynchronisation, offsets, bounded memory."""

import random

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from ktcs_bench.codec import Frame, FrameCodec, Garbage, StreamDecoder, get_profile, profile_names
from ktcs_bench.codec.frame import Record
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError

from .strategies import frames

PROFILES = [get_profile(n) for n in profile_names()]
T1 = get_profile("ktcs-type1")


def decode_chunks(profile, chunks: list[bytes]) -> list[Record]:  # type: ignore[no-untyped-def]
    dec = StreamDecoder(profile)
    out: list[Record] = []
    for c in chunks:
        out += dec.feed(c)
    return out + dec.close()


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in zip(points, points[1:], strict=False)]


def assert_accounts_for_every_byte(records: list[Record], data: bytes) -> None:
    pos = 0
    for r in records:
        assert r.offset == pos, f"record at {r.offset}, expected {pos}"
        if isinstance(r, Frame):  # DATA lies inside the frame's own bytes
            assert 0 <= r.data_start <= r.data_end <= len(r.raw), r
        pos += len(r.raw)
    assert b"".join(r.raw for r in records) == data


# -- a reference model of the framing rules, independent of the decoder -----------------------
def announced_size(profile: FrameProfile, buf: bytes, q: int) -> int | None:
    """The size of the frame an STX at q announces, None if its header is cut short or its LEN
    is out of range."""
    hs = profile.header_size
    if buf[q] != profile.stx or len(buf) - q < hs:
        return None
    names = [n for n, _ in profile.header]
    length = profile.header_struct().unpack_from(buf, q + 1)[names.index("len")]
    data_len = length - profile.fixed_counted
    if data_len < 0 or length > profile.max_len:
        return None
    return profile.frame_size(data_len)


def is_frame(profile: FrameProfile, raw: bytes) -> bool:
    """Whether `raw` is exactly one valid frame: re-encoding its fields gives it back."""
    size = announced_size(profile, raw, 0) if raw else None
    if size != len(raw):
        return False
    names = [n for n, _ in profile.header]
    h = dict(zip(names, profile.header_struct().unpack_from(raw, 1), strict=True))
    hs = profile.header_size
    data = raw[hs : hs + h["len"] - profile.fixed_counted]
    try:
        return FrameCodec(profile).encode(h["seq"], h["op"], data, h.get("sub")) == raw
    except UsageError:
        return False


def valid_frame_inside(profile: FrameProfile, raw: bytes) -> bool:
    for q in range(1, len(raw)):
        size = announced_size(profile, raw, q)
        if size is not None and q + size <= len(raw) and is_frame(profile, raw[q : q + size]):
            return True
    return False


def etx_bears_out_a_false_extent(profile: FrameProfile, stream: bytes, lo: int, hi: int) -> bool:
    """Whether an STX in stream[lo:hi] announces a frame ending past `hi` on an ETX byte: the rule
    takes such a span for one corrupted frame (its price: frames it overlaps are lost)."""
    for k in range(lo, hi):
        size = announced_size(profile, stream, k)
        end = None if size is None else k + size
        if end is not None and hi < end <= len(stream) and stream[end - 1] == profile.etx:
            return True
    return False


@settings(max_examples=200)
@given(
    profile=st.sampled_from(PROFILES),
    data=st.data(),
    garbage=st.lists(st.binary(max_size=40), min_size=1, max_size=6),
    cuts=st.lists(st.integers(0, 10_000), max_size=30),
)
def test_chunking_does_not_change_the_result(profile, data, garbage, cuts) -> None:  # type: ignore[no-untyped-def]
    good = [data.draw(frames(profile)) for _ in range(len(garbage))]
    stream = b"".join(g + f for g, f in zip(garbage, good, strict=True))
    whole = decode_chunks(profile, [stream])
    assert decode_chunks(profile, split(stream, cuts)) == whole
    assert decode_chunks(profile, [bytes([b]) for b in stream]) == whole
    assert_accounts_for_every_byte(whole, stream)


@pytest.mark.requirement("T1-FRAME-03")
@settings(max_examples=200)
@given(profile=st.sampled_from(PROFILES), data=st.data(), garbage=st.binary(max_size=64))
def test_good_frame_after_garbage_is_always_found(profile, data, garbage) -> None:  # type: ignore[no-untyped-def]
    frame = data.draw(frames(profile))
    assume(not etx_bears_out_a_false_extent(profile, garbage + frame, 0, len(garbage)))
    records = decode_chunks(profile, [garbage + frame])
    last = records[-1]
    assert isinstance(last, Frame) and last.error is None and last.raw == frame


@pytest.mark.requirement("T1-FRAME-03")
def test_false_stx_with_long_len_does_not_swallow_the_next_frame() -> None:
    good = FrameCodec(T1).encode(7, 0x0003)
    false_start = bytes([0x02, 0xFF, 0x03, 0x00, 0x00, 0x00])  # announces 1023 DATA bytes
    dec = StreamDecoder(T1)
    records = dec.feed(b"\xaa" + false_start + good)
    frames_ok = [r for r in records if isinstance(r, Frame) and r.ok]
    assert [f.raw for f in frames_ok] == [good], "the good frame must come out without waiting"
    assert isinstance(records[0], Garbage) and records[0].offset == 0


@pytest.mark.requirement("T1-FRAME-02", "SYS-DECODE-01")
def test_length_beyond_max_is_a_length_error_not_an_allocation() -> None:
    dec = StreamDecoder(T1)
    records = dec.feed(bytes([0x02, 0xFF, 0xFF, 0x01, 0x02, 0x00]) + b"\x00" * 10)
    assert isinstance(records[0], Frame) and records[0].error == "length"
    assert dec.buffered <= 16


@pytest.mark.requirement("T1-CRC-01", "T1-FRAME-03")
def test_crc_error_is_reported_once_then_resync() -> None:
    codec = FrameCodec(T1)
    a = bytearray(codec.encode_message(1, "CHANGE", items=[[0x0202, 2], [0x0102, 2]]))
    a[8] ^= 0x10  # corrupt DATA
    b = codec.encode(2, 0x0003)
    records = decode_chunks(T1, [bytes(a) + b])
    errors = [r for r in records if isinstance(r, Frame) and r.error]
    good = [r for r in records if isinstance(r, Frame) and r.ok]
    assert [e.error for e in errors] == ["crc"]
    assert [g.raw for g in good] == [b]


def test_failed_candidate_judged_by_its_own_bytes_whatever_the_chunking() -> None:
    """Garbage `02 03` before a Type II frame: the false candidate fails its CRC and the frame at
    its inner STX ends past it; byte by byte and all at once must say the same (found by
    hypothesis)."""
    t2 = get_profile("ktcs-type2")
    stream = b"\x02\x03" + b"\x02\x03'03\x9d\x9a"
    whole = decode_chunks(t2, [stream])
    assert decode_chunks(t2, [bytes([b]) for b in stream]) == whole
    assert_accounts_for_every_byte(whole, stream)
    assert isinstance(whole[-1], Frame) and whole[-1].ok and whole[-1].offset == 2


def test_bad_all_info_holding_stx_bytes_is_one_error_record() -> None:
    """Issue 12: an ALL_INFO (LEN 110) with a bad CRC whose DATA holds `02 01 00 01 01 ...` was
    two records, cut at the inner STX. Its ETX sits where LEN says: one frame, DATA whole."""
    for profile in (T1, get_profile("ktcs-type1-fig7")):
        statuses = [2, 1, 0, 1, 1] + [0] * (110 - profile.fixed_counted - 5)
        wire = bytearray(FrameCodec(profile).encode_message(0x11, "ALL_INFO", statuses=statuses))
        assert int.from_bytes(wire[1:3], "little") == 110
        crc_at = profile.header_size + len(statuses)
        wire[crc_at] ^= 0x40
        for chunks in ([bytes(wire)], [bytes([b]) for b in wire], split(bytes(wire), [9])):
            (rec,) = decode_chunks(profile, chunks)
            assert isinstance(rec, Frame) and rec.error == "crc" and rec.offset == 0
            assert rec.raw == wire and rec.data == bytes(statuses) and rec.seq == 0x11


def test_bad_change_whose_op_byte_is_stx_is_one_error_record() -> None:
    """Issue 12: a CHANGE with a bad CRC (its OP byte is 0x02) was a 4-byte error record with empty
    DATA and a garbage span after it; a link NAKed twice."""
    good_after = FrameCodec(T1).encode(0x78, 0x0003)
    wire = bytearray(FrameCodec(T1).encode_message(0x77, "CHANGE", items=[[1, 1], [2, 1]]))
    assert wire[T1.offset_of("op")[0]] == 0x02
    wire[T1.header_size + 1] ^= 0x10
    stream = bytes(wire) + good_after
    for chunks in ([stream], [bytes([b]) for b in stream], split(stream, [5, 17])):
        first, second = decode_chunks(T1, chunks)
        assert isinstance(first, Frame) and first.error == "crc" and first.raw == wire
        assert first.data == wire[T1.header_size : T1.header_size + 6] and first.seq == 0x77
        assert isinstance(second, Frame) and second.ok and second.raw == good_after


def test_a_false_stx_whose_len_ends_off_the_etx_still_gives_way_to_the_frame_behind() -> None:
    """Nothing bears out the LEN of a false STX whose LEN-implied end holds no ETX: the error
    record stops at the inner STX that could begin a real frame, and that frame decodes."""
    good = FrameCodec(T1).encode_message(5, "CHANGE", items=[[7, 1], [8, 0], [9, 1]])
    false_start = bytes([0x02, 0x08, 0x00, 0x00, 0x00, 0x00])  # 8 DATA bytes: ends inside `good`
    stream = false_start + good
    assert stream[6 + 8 + 5 - 1] != T1.etx
    records = decode_chunks(T1, [stream])
    assert [r.raw for r in records] == [false_start, good]
    assert isinstance(records[0], Frame) and records[0].error == "crc"
    assert isinstance(records[1], Frame) and records[1].ok


def test_etx_error() -> None:
    wire = bytearray(FrameCodec(T1).encode(3, 0x0003))
    wire[-1] = 0x04
    (rec,) = decode_chunks(T1, [bytes(wire)])
    assert isinstance(rec, Frame) and rec.error == "etx" and rec.crc_ok


def test_truncated_at_end_and_abandon_for_delta_r() -> None:
    wire = FrameCodec(T1).encode(9, 0x0001, bytes(50))
    dec = StreamDecoder(T1)
    assert dec.feed(wire[:20]) == []
    assert dec.pending
    (rec,) = dec.abandon()
    assert isinstance(rec, Frame) and rec.error == "truncated" and rec.seq == 9
    assert not dec.pending
    more = dec.feed(wire)  # the retransmission decodes normally
    assert [r.raw for r in more if isinstance(r, Frame) and r.ok] == [wire]


@pytest.mark.requirement("T1-CRC-01")
@settings(max_examples=150)
@given(profile=st.sampled_from(PROFILES), data=st.data(), n=st.integers(2, 6))
def test_single_bit_flip_loses_only_its_own_frame(profile, data, n) -> None:  # type: ignore[no-untyped-def]
    good = [data.draw(frames(profile)) for _ in range(n)]
    victim = data.draw(st.integers(0, n - 1))
    size = len(good[victim])
    # bytes the profile protects: all of them, except DATA when the CRC stops before it (fig7)
    hs, data_len = profile.header_size, size - profile.frame_size(0)
    unprotected = range(hs, hs + data_len) if profile.crc_last != "data" else range(0)
    byte = data.draw(st.sampled_from([k for k in range(size) if k not in unprotected]))
    bit = 8 * byte + data.draw(st.integers(0, 7))
    hit = bytearray(good[victim])
    hit[bit // 8] ^= 1 << (bit % 8)
    stream = b"".join(bytes(hit) if i == victim else f for i, f in enumerate(good))
    at = sum(len(f) for f in good[:victim])
    assume(not etx_bears_out_a_false_extent(profile, stream, at, at + size))  # LEN or STX hit
    records = decode_chunks(profile, [stream])
    delivered = [r.raw for r in records if isinstance(r, Frame) and r.ok]
    expected = [f for i, f in enumerate(good) if i != victim]
    assert delivered == expected
    assert_accounts_for_every_byte(records, stream)


def test_random_bulk_garbage_is_fully_accounted() -> None:
    rng = random.Random(1234)
    for profile in PROFILES:
        data = bytes(rng.choice([0x02, 0x03, 0x00, rng.randrange(256)]) for _ in range(20_000))
        records = decode_chunks(profile, [data])
        assert_accounts_for_every_byte(records, data)


@settings(max_examples=300)
@given(
    profile=st.sampled_from(PROFILES),
    data=st.data(),
    cuts=st.lists(st.integers(0, 10_000), max_size=20),
)
def test_a_frame_with_bits_flipped_in_data_or_crc_is_one_record_at_its_offset(
    profile: FrameProfile, data: st.DataObject, cuts: list[int]
) -> None:
    """Issue 12: whatever STX bytes the corruption leaves in DATA or CRC, and however the input is
    chunked, a Type I frame gives exactly one record, at its offset, holding its bytes (error
    `crc` with DATA whole; or a good frame where the profile leaves DATA unprotected). Type II has
    no ETX to bear its LEN out: its record stops at the first inner STX that could begin a frame
    ending past it, and no good frame comes out of the corrupted bytes."""
    before = [data.draw(frames(profile)) for _ in range(data.draw(st.integers(0, 2)))]
    after = [data.draw(frames(profile)) for _ in range(data.draw(st.integers(0, 2)))]
    frame = data.draw(frames(profile))
    hs = profile.header_size
    data_len = len(frame) - profile.frame_size(0)
    first, last = 8 * hs, 8 * (hs + data_len + profile.crc_size) - 1  # bits of DATA and CRC
    bits = data.draw(st.sets(st.integers(first, last), min_size=1, max_size=8))
    hit = bytearray(frame)
    for b in bits:
        hit[b // 8] ^= 1 << (b % 8)
    corrupted = bytes(hit)
    assume(not valid_frame_inside(profile, corrupted))  # the rule: a frame inside it wins
    # a pattern of flipped bits the CRC cannot see (CRC-16 misses some of 4 or more) leaves a
    # valid frame where the CRC covers DATA: the check's limit, not the decoder's
    assume(profile.crc_last != "data" or not is_frame(profile, corrupted))
    at = sum(map(len, before))
    stream = b"".join(before) + corrupted + b"".join(after)
    whole = decode_chunks(profile, [stream])
    assert decode_chunks(profile, split(stream, cuts)) == whole
    assert decode_chunks(profile, [bytes([b]) for b in stream]) == whole
    assert_accounts_for_every_byte(whole, stream)
    assert [r.raw for r in whole[: len(before)]] == before
    rec = whole[len(before)]
    assert isinstance(rec, Frame) and rec.offset == at
    if profile.etx is not None:
        assert rec.raw == corrupted
        assert [r.raw for r in whole[len(before) + 1 :]] == after
        assert all(isinstance(r, Frame) and r.ok for r in whole if r is not rec)
        if rec.error is None:
            assert profile.crc_last != "data"  # only where the CRC leaves DATA unprotected
        else:
            assert rec.error == "crc" and rec.data == corrupted[hs : hs + data_len]
        return
    cut = next(
        (q for q in range(1, len(corrupted)) if corrupted[q] == profile.stx
         and (len(corrupted) - q < hs or (size := announced_size(profile, corrupted, q)) is not None
              and q + size > len(corrupted))),
        len(corrupted),
    )  # fmt: skip
    assert rec.error == "crc" and rec.raw == corrupted[:cut]
    inside = [r for r in whole if at <= r.offset < at + len(corrupted)]
    assert not any(isinstance(r, Frame) and r.ok for r in inside)
    assert [r.raw for r in whole if isinstance(r, Frame) and r.ok] == before + after


class _FullPass(StreamDecoder):
    """The decoder with a full pass over its buffer on every feed: what `feed` skips for a
    frame's pieces must give the same records, at the same feeds."""

    def feed(self, data: bytes | bytearray | memoryview) -> list[Record]:
        self._buf += data
        return self._process(final=False)


@settings(max_examples=300)
@given(
    profile=st.sampled_from(PROFILES),
    data=st.data(),
    parts=st.lists(
        st.tuples(st.sampled_from(["frame", "garbage", "flipped", "cut"]), st.integers(0, 1 << 16)),
        min_size=1,
        max_size=8,
    ),
    pieces=st.lists(st.integers(1, 40), min_size=1, max_size=40),
    abandon_at=st.sets(st.integers(0, 60), max_size=4),
)
def test_a_frame_fed_in_pieces_decodes_as_with_a_full_pass_on_every_piece(
    profile: FrameProfile,
    data: st.DataObject,
    parts: list[tuple[str, int]],
    pieces: list[int],
    abandon_at: set[int],
) -> None:
    """A line hands a frame over in pieces; the decoder takes a piece that cannot end the pending
    frame without a pass over its buffer. Frames, garbage, corrupted and cut frames, in pieces of
    any size, ΔR abandoning anywhere: the records of every call are those of a full pass."""
    stream = b""
    for kind, r in parts:
        frame = data.draw(frames(profile))
        if kind == "garbage":
            frame = random.Random(r).randbytes(r % 24)
        elif kind == "flipped":
            hit = bytearray(frame)
            hit[r % len(hit)] ^= 1 << (r % 8)
            frame = bytes(hit)
        elif kind == "cut":
            frame = frame[: r % len(frame)]
        stream += frame
    fast, full = StreamDecoder(profile), _FullPass(profile)
    pos, k = 0, 0
    while pos < len(stream):
        size = pieces[k % len(pieces)]
        chunk, pos = stream[pos : pos + size], pos + size
        assert fast.feed(chunk) == full.feed(chunk)
        assert fast.pending == full.pending and fast.buffered == full.buffered
        if k in abandon_at:
            assert fast.abandon() == full.abandon()
        k += 1
    assert fast.close() == full.close()


def test_a_first_piece_holding_a_cut_frame_and_a_whole_one_gives_the_whole_one() -> None:
    """The STX of a frame cut short, then a whole frame, in one piece: the whole frame comes out
    at once (the cut one's LEN announces more than the piece holds)."""
    codec = FrameCodec(T1)
    cut = codec.encode(1, 0x0010, bytes(40))[:9]
    whole = codec.encode(2, 0x0010, b"")
    for decoder in (StreamDecoder(T1), _FullPass(T1)):
        records = decoder.feed(cut + whole)
        assert [r.raw for r in records] == [cut, whole]
