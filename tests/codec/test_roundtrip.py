"""Encode -> decode is the identity, for every opcode of every shipped profile."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.codec import FrameCodec, StreamDecoder, get_profile, profile_names

from .strategies import messages

PROFILES = [get_profile(n) for n in profile_names()]


@pytest.mark.requirement("T1-FRAME-01", "T2-FRAME-01")
@settings(max_examples=400)
@given(data=st.data(), profile=st.sampled_from(PROFILES))
def test_encode_decode_roundtrip(data: st.DataObject, profile) -> None:  # type: ignore[no-untyped-def]
    seq, opcode, sub, values = data.draw(messages(profile))
    wire = FrameCodec(profile).encode(seq, opcode.op, opcode.build(values), sub)
    dec = StreamDecoder(profile)
    (frame,) = dec.feed(wire) + dec.close()
    assert frame.error is None and frame.raw == wire
    assert (frame.seq, frame.op, frame.sub) == (seq, opcode.op, sub)
    assert opcode.parse(frame.data) == values


def test_every_opcode_is_covered_by_the_strategy() -> None:
    # the round trip samples opcodes from the table itself, so a new YAML opcode is covered
    for profile in PROFILES:
        assert len(profile.opcodes.by_op) >= 6
