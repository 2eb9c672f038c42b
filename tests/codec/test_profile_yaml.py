"""Wire formats are data: a profile that exists only in this test's YAML decodes and encodes,
and a broken profile gives one message naming the file, the key and the problem."""

from pathlib import Path

import pytest

from ktcs_bench.codec import FrameCodec, StreamDecoder
from ktcs_bench.codec.profile import get_profile, load_profiles
from ktcs_bench.errors import ConfigError

VENDOR = """\
protocol: type1
crc_algorithms:
  crc-16/arc: {poly: 0x18005, reflect: true, init: 0, xor_out: 0, check: 0xBB3D}
  crc-16/ccitt-false: {poly: 0x11021, reflect: false, init: 0xFFFF, xor_out: 0, check: 0x29B1}
profiles:
  vendor-x:
    description: big-endian, STX 0x7E, 1-byte LEN counting SEQ+OP+DATA, CCITT CRC over LEN..DATA
    stx: 0x7E
    etx: 0x7F
    byte_order: big
    header:
      - {name: len, size: 1}
      - {name: seq, size: 1}
      - {name: op, size: 2}
    length_counts: [seq, op, data]
    max_len: 200
    crc: {algorithm: crc-16/ccitt-false, covers: [len, data], size: 2, pad: 0}
opcodes:
  - {op: 0x0102, name: CHANGE, items: [{name: code, type: u16}, {name: state, type: u8}]}
  - {op: 0x0003, name: LINK_TEST}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "vendor.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_profile_only_in_yaml_encodes_and_decodes(tmp_path: Path) -> None:
    path = write(tmp_path, VENDOR)
    profile = get_profile(f"{path}:vendor-x")
    wire = FrameCodec(profile).encode_message(9, "CHANGE", items=[[0x0203, 1]])
    # 7E | LEN=1+2+3 | SEQ 09 | OP 01 02 (big-endian) | 02 03 01 | CRC (big-endian) | 7F
    assert wire[:8] == bytes([0x7E, 6, 9, 0x01, 0x02, 0x02, 0x03, 0x01])
    assert wire[-1] == 0x7F and len(wire) == 11
    from ktcs_bench.codec.crc import CrcSpec

    ccitt = CrcSpec("x", 0x11021, False, 0xFFFF, 0).function()
    assert int.from_bytes(wire[8:10], "big") == ccitt(wire[1:8])
    dec = StreamDecoder(profile)
    (frame,) = dec.feed(b"\x00\x7e" + wire)[1:] + dec.close()
    assert frame.ok and frame.op == 0x0102
    assert profile.opcodes.by_name["CHANGE"].parse(frame.data) == {"items": [[0x0203, 1]]}


BROKEN = [
    ("    stx: 0x7E\n", "", "profiles.vendor-x.stx", "missing key"),
    (
        "max_len: 200",
        "max_len: 300",
        "profiles.vendor-x.max_len",
        "does not fit the 1-byte len field",
    ),
    (
        "size: 2, pad: 0",
        "size: 1, pad: 0",
        "profiles.vendor-x.crc.size",
        "cannot carry a 16-bit CRC",
    ),
    (
        "covers: [len, data]",
        "covers: [len, nowhere]",
        "profiles.vendor-x.crc.covers",
        "must be [first, last]",
    ),
    (
        "{name: seq, size: 1}",
        "{name: seq, size: 3}",
        "profiles.vendor-x.header[1].size",
        "must be 1, 2 or 4",
    ),
    ("check: 0x29B1", "check: 0x1234", "crc_algorithms.crc-16/ccitt-false", "check value"),
    (
        "type: u16}, {name: state",
        "type: u12}, {name: state",
        "opcodes[0].items[0].type",
        "must be u8, u16 or u32",
    ),
    (
        "byte_order: big",
        "byte_order: middle",
        "profiles.vendor-x.byte_order",
        "must be little or big",
    ),
    (
        "length_counts: [seq, op, data]",
        "length_counts: [seq, op]",
        "profiles.vendor-x.length_counts",
        "LEN must count data",
    ),
    ("etx: 0x7F", "etx: 0x17F", "profiles.vendor-x.etx", "must be a byte value"),
]

# Issue 13: each of these gave a traceback or a silently wrong codec.
CRC_LINE = "crc: {algorithm: crc-16/ccitt-false, covers: [len, data], size: 2, pad: 0}"
WHOLE = [
    ("poly: 0x11021", "poly: 0", "crc_algorithms.crc-16/ccitt-false.poly", "must be a polynomial"),
    (
        "poly: 0x11021",
        "poly: 0x1" + "0" * 40,
        "crc_algorithms.crc-16/ccitt-false.poly",
        "must be a polynomial",
    ),
    ("init: 0xFFFF", "init: 0x1FFFF", "crc_algorithms.crc-16/ccitt-false.init", "must be 0x0..0xffff"),
    (CRC_LINE, CRC_LINE + "\n    opcode_overrides: 7", "profiles.vendor-x.opcode_overrides",
     "must be a list of opcodes"),
    ("name: LINK_TEST}", "name: change}", "opcodes[1].name", "opcode name CHANGE is also opcodes[0]"),
    ("op: 0x0003,", "op: 0x0102,", "opcodes[1].op", "opcode 0x0102 is also opcodes[0]"),
    (
        CRC_LINE,
        CRC_LINE + "\n    opcode_overrides: [{op: 0x0003, name: CHANGE}]",
        "profiles.vendor-x.opcode_overrides[0].name",
        "opcode name CHANGE is also opcodes[0]",
    ),
    ("size: 2, pad: 0", "size: 2, pad: 100000000", "profiles.vendor-x.crc.pad", "must be 0..16"),
    ("op: 0x0003,", "op: 0x10000,", "opcodes[1].op", "must be 0x0..0xffff, not 0x10000"),
    ("op: 0x0003,", "op: -1,", "opcodes[1].op", "must be 0x0..0xffff, not -0x1"),
    (
        "{name: op, size: 2}",
        "{name: op, size: 1}",
        "opcodes[0].op",
        "0x102 does not fit the 1-byte op field",
    ),
    ("    etx: 0x7F\n", "    etx: 0x7F\n    ext: 0x03\n", "profiles.vendor-x.ext", "unknown key"),
    ("name: LINK_TEST}", "name: LINK_TEST, statuses: yes please}", "opcodes[1].statuses",
     "must be true or false"),
    (
        "length_counts: [seq, op, data]",
        "length_counts: [seq, sub, data]",
        "profiles.vendor-x.length_counts[1]",
        "must be one of seq, op, data",
    ),
]  # fmt: skip


@pytest.mark.parametrize(
    ("old", "new", "place", "problem"),
    BROKEN + WHOLE,
    ids=[f"{b[2]}:{b[1]}" for b in BROKEN + WHOLE],
)
def test_broken_profile_is_one_clear_message(
    tmp_path: Path, old: str, new: str, place: str, problem: str
) -> None:
    assert old in VENDOR
    path = write(tmp_path, VENDOR.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_profiles(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert info.value.place == place, message
    assert problem in message, message


def test_yaml_syntax_error_names_line(tmp_path: Path) -> None:
    path = write(tmp_path, VENDOR.replace("    etx: 0x7F\n", "    etx: [0x7F\n", 1))
    with pytest.raises(ConfigError) as info:
        load_profiles(path)
    assert str(path) in str(info.value) and "line" in info.value.place


@pytest.mark.parametrize(("old", "new", "place", "problem"), WHOLE, ids=[w[1] for w in WHOLE])
def test_cli_reports_broken_profile_without_traceback(
    tmp_path: Path, old: str, new: str, place: str, problem: str
) -> None:
    import subprocess
    import sys

    path = write(tmp_path, VENDOR.replace(old, new, 1))
    out = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "decode", "--profile", f"{path}:vendor-x",
         "7e 00 00 00 00"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert f"{path}: {place}: " in out.stderr and problem in out.stderr, out.stderr
    assert out.stderr.count("\n") == 1, "one message"


def test_a_profile_key_of_the_wrong_type_names_its_line(tmp_path: Path) -> None:
    """A profile's shape is declared: a mistyped value is refused at its key, on its line (the
    line looked up in the file as written, past the profile's comment lines)."""
    path = write(tmp_path, VENDOR.replace("    max_len: 200", "    # how long\n    max_len: long"))
    with pytest.raises(ConfigError) as info:
        load_profiles(path)
    assert info.value.place == "profiles.vendor-x.max_len"
    line = path.read_text().splitlines().index("    max_len: long") + 1
    assert info.value.problem == f"must be an integer, not str (line {line})"
