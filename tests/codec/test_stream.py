"""The streaming decoder: any chunking, resynchronisation, offsets, bounded memory."""

import random

from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.codec import Frame, FrameCodec, Garbage, StreamDecoder, get_profile, profile_names
from ktcs_bench.codec.frame import Record

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


@settings(max_examples=200)
@given(profile=st.sampled_from(PROFILES), data=st.data(), garbage=st.binary(max_size=64))
def test_good_frame_after_garbage_is_always_found(profile, data, garbage) -> None:  # type: ignore[no-untyped-def]
    frame = data.draw(frames(profile))
    records = decode_chunks(profile, [garbage + frame])
    last = records[-1]
    assert isinstance(last, Frame) and last.error is None and last.raw == frame


def test_false_stx_with_long_len_does_not_swallow_the_next_frame() -> None:
    good = FrameCodec(T1).encode(7, 0x0003)
    false_start = bytes([0x02, 0xFF, 0x03, 0x00, 0x00, 0x00])  # announces 1023 DATA bytes
    dec = StreamDecoder(T1)
    records = dec.feed(b"\xaa" + false_start + good)
    frames_ok = [r for r in records if isinstance(r, Frame) and r.ok]
    assert [f.raw for f in frames_ok] == [good], "the good frame must come out without waiting"
    assert isinstance(records[0], Garbage) and records[0].offset == 0


def test_length_beyond_max_is_a_length_error_not_an_allocation() -> None:
    dec = StreamDecoder(T1)
    records = dec.feed(bytes([0x02, 0xFF, 0xFF, 0x01, 0x02, 0x00]) + b"\x00" * 10)
    assert isinstance(records[0], Frame) and records[0].error == "length"
    assert dec.buffered <= 16


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


def test_crc_error_cut_at_an_inner_stx_keeps_data_inside_the_record() -> None:
    """A bad CHANGE whose OP byte is STX (0x02) is reported up to that STX, then resynchronised."""
    wire = bytearray(FrameCodec(T1).encode_message(0x77, "CHANGE", items=[[1, 1], [1, 1]]))
    wire[T1.header_size + 5] ^= 0x02
    records = decode_chunks(T1, [bytes(wire)])
    assert_accounts_for_every_byte(records, bytes(wire))
    first = records[0]
    assert isinstance(first, Frame) and first.error == "crc" and first.seq == 0x77
    assert first.data == first.raw[first.data_start :] and len(first.raw) < len(wire)


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
