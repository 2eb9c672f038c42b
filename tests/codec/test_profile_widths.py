"""Issue 22 part 4b: what the links, the code port and the threat campaign take from the wire
format -- NAK reason numbers, how many items fit in a frame, where an item's state sits -- comes
from the profile, so a vendor's variant (other header, wider items, other reason numbers, a
smaller frame) added only as YAML works with no Python change."""

from __future__ import annotations

from pathlib import Path

import pytest

from ktcs_bench.codec import FrameCodec, StreamDecoder, get_profile
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import ConfigError, UsageError
from ktcs_bench.threats.campaign import corrupted_change
from ktcs_bench.type1.events import NakSent
from ktcs_bench.type1.link import Type1Link
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ctc_side import CtcConnection

SHIPPED = Path(__file__).resolve().parents[2] / "protocols"


def vendor_type1(tmp_path: Path) -> FrameProfile:
    """The shipped Type I file with a vendor's profile: a 1-byte LEN and OP, SEQ first, big-endian,
    64 bytes of DATA at most, CHANGE items of a u32 code and a u16 state, reasons 7, 8, 9."""
    text = (SHIPPED / "type1.yaml").read_text()
    text = text.replace(
        "  ktcs-type1-fig7:",
        """  acme-type1:
    description: a vendor's variant
    stx: 0x02
    etx: 0x03
    byte_order: big
    header: [{name: seq, size: 1}, {name: len, size: 1}, {name: op, size: 1}]
    length_counts: [data]
    max_len: 64
    crc: {algorithm: crc-16/arc, covers: [stx, data], size: 2, pad: 0}
    opcode_overrides:
      - {op: 0x0002, name: CHANGE, items: [{name: code, type: u32}, {name: state, type: u16}]}

  ktcs-type1-fig7:""",
    )
    old = "nak_reasons:\n  1: crc error\n  2: frame timeout (ΔR)\n  3: length/format error\n"
    assert old in text
    text = text.replace(
        old, "nak_reasons:\n  7: crc error\n  8: frame timeout\n  9: length/format error\n"
    )
    path = tmp_path / "acme1.yaml"
    path.write_text(text)
    return get_profile(f"{path}:acme-type1")


def test_a_type1_link_naks_with_the_vendor_profiles_reason_numbers(tmp_path: Path) -> None:
    profile = vendor_type1(tmp_path)
    a, b = Type1Link(profile, name="a"), Type1Link(profile, name="b")
    a.send(a.message("CHANGE", items=[[70_000, 300]]), 0.0)
    frame = bytearray(a.data_to_send(0.0))
    frame[profile.header_size] ^= 0x01  # a bit of DATA: the CRC no longer checks
    events = b.receive_data(bytes(frame), 0.1)
    (nak,) = [e for e in events if isinstance(e, NakSent)]
    assert (nak.reason, nak.reason_name) == (7, "crc error")
    (sent,) = StreamDecoder(profile).feed(b.data_to_send(0.1))
    assert sent.ok and sent.op == profile.opcodes.by_name["NAK"].op and sent.data == bytes([7])
    # an opcode the profile does not know: the vendor's length/format reason
    raw = FrameCodec(profile).encode(5, 0x7E, b"")
    events = b.receive_data(raw, 0.2)
    assert [e.reason for e in events if isinstance(e, NakSent)] == [9]


def test_a_profile_that_names_no_reason_the_link_needs_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "acme1.yaml"
    vendor_type1(tmp_path)
    path.write_text(path.read_text().replace("  8: frame timeout\n", ""))
    with pytest.raises(ConfigError, match="needs 'frame timeout'"):
        Type1Link(get_profile(f"{path}:acme-type1"))


def test_items_a_frame_carries_follow_the_profiles_widths(tmp_path: Path) -> None:
    """The code port splits CHANGE into frames of `items_per_frame` items: 10 six-byte items in
    the vendor's 64 bytes of DATA, 341 three-byte ones in the default profile's 1024."""
    profile = vendor_type1(tmp_path)
    assert profile.items_per_frame("CHANGE") == 10
    assert get_profile("ktcs-type1").items_per_frame("CHANGE") == 341
    link = Type1Link(profile)
    link.send(link.message("CHANGE", items=[[k, 1] for k in range(10)]), 0.0)  # fits
    with pytest.raises(UsageError, match="exceed"):
        link.send(link.message("CHANGE", items=[[k, 1] for k in range(11)]), 0.0)


@pytest.mark.parametrize("name", ["ktcs-type1", "vendor"])
def test_the_corruption_threat_flips_a_bit_of_the_second_items_state(
    tmp_path: Path, name: str
) -> None:
    profile = vendor_type1(tmp_path) if name == "vendor" else get_profile(name)
    frame = corrupted_change(profile, 0x11, 1234, 1)
    (rec,) = StreamDecoder(profile).feed(frame)
    assert rec.error == "crc"  # refused on the CRC, as the threat means
    opcode = profile.opcodes.by_name["CHANGE"]
    data = frame[profile.header_size : profile.header_size + 2 * opcode.item_size]
    assert opcode.items_of(data) == [[1234, 1], [1234, 1 ^ 0x02]]


def test_a_type2_session_naks_with_the_vendor_profiles_reason_numbers(tmp_path: Path) -> None:
    text = (SHIPPED / "type2.yaml").read_text()
    old = "nak_reasons:\n  1: crc error\n  3: length/format error\n  4: unknown opcode\n"
    assert old in text
    text = text.replace(
        old, "nak_reasons:\n  5: crc error\n  6: length/format error\n  7: unknown opcode\n"
    )
    text = text.replace("subs: {1: crc error, 3: length/format error, 4: unknown opcode}",
                        "subs: {5: crc error, 6: length/format error, 7: unknown opcode}")  # fmt: skip
    path = tmp_path / "acme2.yaml"
    path.write_text(text)
    config = Type2Config(profile=f"{path}:ktcs-type2")
    profile = get_profile(config.profile)
    ctc = CtcConnection(0.0, config)
    events = ctc.receive_data(FrameCodec(profile).encode(0, 0x77, b"", 0), 0.1)
    bad = [e for e in events if isinstance(e, ev.BadFrameReceived)]
    assert [b.reason for b in bad] == [7]  # an unknown opcode, in the vendor's number
    naks = [f for f in StreamDecoder(profile).feed(ctc.data_to_send()) if f.op == 0x15]
    assert [f.sub for f in naks] == [7]
