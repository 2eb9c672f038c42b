"""Every hex form of SPEC §7 gives the same bytes."""

import pytest

from ktcs_bench.codec.hextext import parse_hex_text

FRAME = bytes.fromhex("0200001006000387000003")

FORMS = {
    "angle": "<02><00><00><10><06><00><03><87><00><00><03>",
    "brackets": "[02][00][00][10][06][00][03][87][00][00][03]",
    "spaced": "02 00 00 10 06 00 03 87 00 00 03",
    "compact": "0200001006000387000003",
    "c-array": "0x02, 0x00, 0x00, 0x10, 0x06, 0x00, 0x03, 0x87, 0x00, 0x00, 0x03",
    "xxd": "00000000: 0200 0010 0600 0387 0000 03             ...........",
    "hexdump-C": "00000000  02 00 00 10 06 00 03 87  00 00 03                 |...........|",
    "console": "수신 = <02><00><00><10><06><00><03><87><00><00><03>",
    "wrapped": "송신 = [02][00][00][10][06]\n      [00][03][87][00][00][03]",
    "hexlog": "12.500000 ixl>atc 02 00 00 10 06 00 03 87 00 00 03",
}


@pytest.mark.parametrize("form", FORMS)
def test_form(form: str) -> None:
    assert parse_hex_text(FORMS[form]).data == FRAME


def test_annotations_skipped_and_origin_kept() -> None:
    text = "RX: 02 00\nPacket = [F1]-[E7], Cal = [00]-[00]\n3.25 a>b 0a0b  # comment\n"
    parsed = parse_hex_text(text)
    assert parsed.data == bytes([2, 0, 0x0A, 0x0B])
    assert parsed.skipped_lines == [2]
    second = parsed.origin(2)
    assert second is not None and second.time == 3.25 and second.direction == "a>b"
    first = parsed.origin(1)
    assert first is not None and first.direction == "rx" and first.line == 1


def test_odd_digit_groups_are_not_hex() -> None:
    assert parse_hex_text("020").data == b""
