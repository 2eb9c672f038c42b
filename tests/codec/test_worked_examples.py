"""SPEC §3.6 and §4 worked examples, byte for byte, both directions."""

import pytest

from ktcs_bench.codec import FrameCodec, StreamDecoder, get_profile

TYPE1 = [
    (
        0x10,
        "REQUEST_ALL",
        None,
        {"start": 0, "count": 0xFFFF},
        "02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03",
    ),
    (0x10, "ACK", None, {}, "02 00 00 10 06 00 03 87 00 00 03"),
    (0x11, "NAK", None, {"reason": 1}, "02 01 00 11 15 00 01 F7 29 00 00 03"),
    (
        0x05,
        "CHANGE",
        None,
        {"items": [[3, 1], [260, 0]]},
        "02 06 00 05 02 00 03 00 01 04 01 00 18 58 00 00 03",
    ),
    (
        0x11,
        "ALL_INFO",
        None,
        {"statuses": [1, 1, 1, 1, 0, 0, 0, 0]},
        "02 08 00 11 01 00 01 01 01 01 00 00 00 00 F0 6E 00 00 03",
    ),
]
TYPE2 = [
    (0, "IDENT", 0, {"station": 20, "version": 1}, "02 06 00 01 00 14 00 01 5B DD"),
    (7, "INDICATION", 0, {"items": [[5, 1], [300, 0]]}, "02 09 07 10 00 05 00 01 2C 01 00 3D 5B"),
    (1, "REQUEST_ALL", 0, {}, "02 03 01 30 00 3C 44"),
    (2, "HEARTBEAT", 0, {}, "02 03 02 40 00 E9 84"),
]


@pytest.mark.parametrize(
    ("profile_name", "case"),
    [("ktcs-type1", c) for c in TYPE1] + [("ktcs-type2", c) for c in TYPE2],
    ids=lambda v: v if isinstance(v, str) else v[1],
)
def test_worked_example(profile_name: str, case: tuple) -> None:  # type: ignore[type-arg]
    seq, name, sub, values, expected_hex = case
    profile = get_profile(profile_name)
    expected = bytes.fromhex(expected_hex)
    assert FrameCodec(profile).encode_message(seq, name, sub, **values) == expected
    dec = StreamDecoder(profile)
    (frame,) = dec.feed(expected) + dec.close()
    assert frame.error is None and frame.crc_ok
    opcode = profile.opcodes.by_name[name]
    assert (frame.seq, frame.op) == (seq, opcode.op)
    parsed = opcode.parse(frame.data)
    for key, value in values.items():
        assert parsed[key] == value
