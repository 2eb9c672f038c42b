"""Bad input: random bytes, truncations and bit flips only ever give typed records, never raise."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.codec import Frame, Garbage, StreamDecoder, get_profile, profile_names
from ktcs_bench.codec.hextext import parse_hex_text
from ktcs_bench.codec.render import to_json, to_text

from .strategies import frames

PROFILES = [get_profile(n) for n in profile_names()]
ERRORS = {None, "crc", "etx", "length", "truncated"}


def _check(profile, stream: bytes) -> None:  # type: ignore[no-untyped-def]
    dec = StreamDecoder(profile)
    records = []
    for i in range(0, len(stream), 7):
        records += dec.feed(stream[i : i + 7])
        assert dec.buffered <= profile.frame_size(profile.max_data) + 4096 + 7
    records += dec.close()
    for r in records:
        assert isinstance(r, Frame | Garbage)
        if isinstance(r, Frame):
            assert r.error in ERRORS
        to_json(r, profile)  # rendering never raises either
        to_text(r, profile)
    assert b"".join(r.raw for r in records) == stream


@pytest.mark.requirement("SYS-DECODE-01")
@settings(max_examples=300)
@given(profile=st.sampled_from(PROFILES), stream=st.binary(max_size=600))
def test_random_bytes(profile, stream) -> None:  # type: ignore[no-untyped-def]
    _check(profile, stream)


@pytest.mark.requirement("SYS-DECODE-01", "T1-CRC-01")
@settings(max_examples=300)
@given(profile=st.sampled_from(PROFILES), data=st.data())
def test_truncations_and_bit_flips_of_valid_frames(profile, data) -> None:  # type: ignore[no-untyped-def]
    wire = bytearray(b"".join(data.draw(frames(profile)) for _ in range(3)))
    for pos in data.draw(st.lists(st.integers(0, len(wire) * 8 - 1), max_size=8)):
        wire[pos // 8] ^= 1 << (pos % 8)
    cut = data.draw(st.integers(0, len(wire)))
    _check(profile, bytes(wire[:cut]))


@settings(max_examples=300)
@given(text=st.text(max_size=300))
def test_hex_text_parser_never_raises(text: str) -> None:
    parsed = parse_hex_text(text)
    assert parsed.data == b"".join(bytes(c.data) for c in parsed.chunks)
