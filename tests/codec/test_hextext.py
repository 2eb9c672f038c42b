"""Every hex form of SPEC §7 gives the same bytes."""

import random
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.codec.hextext import (
    REPEAT_PIECE,
    TEXT_WINDOW,
    HexTextParser,
    TextWatch,
    binary_from,
    parse_hex_text,
    text_encoding,
)

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


# -- dumps: the offset column is not data, `*` is expanded, word dumps are never guessed --------
def _capture() -> bytes:
    """Two frames with 40 zero bytes between them: dumps fold the zeros into a `*` line."""
    return bytes.fromhex("02040010000000 84F1E703") + bytes(40) + FRAME


DUMPS = ["hexdump -C", "od -t x1", "od -A x -t x1z", "od -A d -t x1", "od -A x -t x1 -w8", "xxd",
         "xxd -a", "hexdump -C -v"]  # fmt: skip


@pytest.mark.parametrize("command", DUMPS)
def test_dump_of_a_real_tool_gives_the_bytes_back(command: str, tmp_path: Path) -> None:
    path = tmp_path / "cap.bin"
    path.write_bytes(_capture())
    text = subprocess.run([*command.split(), str(path)], capture_output=True, text=True, check=True)
    parsed = parse_hex_text(text.stdout)
    assert parsed.data == _capture(), text.stdout
    assert parsed.skipped_lines == [] and parsed.word_dump_lines == 0


def test_a_folded_run_is_expanded_from_the_offsets_in_their_radix() -> None:
    line = bytes([2]) + bytes(15)
    row = " ".join(f"{b:02x}" for b in line)
    # od's default offsets are octal: 0000060 is byte 48, so `*` left out two copies of the line
    octal = f"0000000 {row}\n*\n0000060 03\n0000061\n"
    assert parse_hex_text(octal).data == line * 3 + b"\x03"
    # the same dump with decimal offsets (od -A d): 0000048 is byte 48
    decimal = f"0000000 {row}\n0000016 {row}\n*\n0000048 05\n0000049\n"
    assert parse_hex_text(decimal).data == line * 3 + b"\x05"
    # the closing offset alone says how long a folded run at the end was (hexdump -C, hex)
    tail = f"00000000  {row}  |................|\n*\n00000040\n"
    assert parse_hex_text(tail).data == line * 4


def test_a_huge_folded_run_is_expanded_in_bounded_pieces() -> None:
    parser = HexTextParser()
    first = "00000000  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|"
    assert list(parser.feed(first)) == [bytes(16)]
    assert list(parser.feed("*")) == []
    pieces = parser.feed("40000000")  # 1 GiB of zeros announced by three lines of text
    first_piece = next(iter(pieces))
    assert len(first_piece) <= REPEAT_PIECE and not any(first_piece)


@pytest.mark.parametrize("command", ["od", "od -x", "hexdump"])
def test_two_byte_word_dumps_are_skipped_not_guessed(command: str, tmp_path: Path) -> None:
    path = tmp_path / "cap.bin"
    path.write_bytes(_capture())
    text = subprocess.run([*command.split(), str(path)], capture_output=True, text=True, check=True)
    parsed = parse_hex_text(text.stdout)
    assert parsed.data == b"" and parsed.word_dump_lines >= 3


# -- text files in the encodings Korean consoles save -------------------------------------------
def test_text_encoding_of_utf8_cp949_euc_kr_and_binary() -> None:
    line = "수신 = <02><04><00><10>\n"
    assert text_encoding(line.encode("utf-8")) == "utf-8"
    assert text_encoding(line.encode("euc-kr")) == "cp949"
    assert text_encoding(line.encode("cp949")) == "cp949"
    assert text_encoding(line.encode("utf-8")[:4]) == "utf-8"  # cut inside a character
    assert text_encoding(bytes(range(256)) * 4) is None
    assert text_encoding(Path(sys.executable).read_bytes()[:65536]) is None


# -- where a stream stops being text (issue 21 item 8) -------------------------------------------
CONSOLE = "수신 = <02><04><00><10>\n\x1b[31mPacket = [F1]-[E7]\x1b[0m\r\n\t송신 = [02][84]\n"


@pytest.mark.parametrize("encoding", ["utf-8", "cp949", "utf-16"])
def test_text_is_text_to_its_end_and_a_binary_tail_is_found_where_it_starts(
    encoding: str,
) -> None:
    text = (CONSOLE * 20_000).encode(encoding)  # megabytes, colours, tabs, CRs
    assert text_encoding(text[:TEXT_WINDOW]) in (encoding, "cp949")
    assert binary_from(text, encoding) is None
    tail = random.Random(4).randbytes(200_000)
    at = binary_from(text + tail, encoding)
    assert at is not None
    if encoding != "utf-16":  # UTF-16 is judged on characters: random ones are rarely controls
        assert len(text) <= at < len(text) + 64


@settings(max_examples=50, deadline=None)
@given(cuts=st.lists(st.integers(0, 400_000), max_size=8), binary=st.booleans())
def test_the_verdict_does_not_depend_on_how_the_stream_was_read(
    cuts: list[int], binary: bool
) -> None:
    data = (CONSOLE * 4000).encode("utf-8")
    if binary:
        data = data[:150_000] + random.Random(1).randbytes(50_000) + data[150_000:]
    watch = TextWatch("utf-8")
    found = None
    edges = [0, *sorted(cuts), len(data)]
    for a, b in zip(edges, edges[1:], strict=False):
        found = watch.feed(data[a:b]) if found is None else found
    found = watch.close() if found is None else found
    assert found == binary_from(data, "utf-8")
    assert (found is not None) == binary


def test_a_few_control_bytes_at_the_end_are_not_a_binary_tail() -> None:
    text = (CONSOLE * 10_000).encode("utf-8")
    assert binary_from(text + b"\x1a", "utf-8") is None  # DOS's end-of-file mark
    assert binary_from(b"02 04 00\x07\n", "utf-8") is not None  # a short file is its head
