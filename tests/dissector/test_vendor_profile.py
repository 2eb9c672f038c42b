"""A vendor's profiles added only as YAML (in a temporary folder, nothing else touched) are
dissected: other STX, no ETX, SEQ before LEN, big-endian fields, a 2-byte SEQ, CRC-16/XMODEM (not
reflected) over LEN..DATA with a pad byte, a CRC-32, opcodes and payloads of its own, and a
Type II variant -- tshark agrees with `ktcs-bench decode --json --profile FILE.yaml:NAME`."""

from __future__ import annotations

import random
from pathlib import Path

from ktcs_bench.capture import CaptureRecord
from ktcs_bench.codec.frame import FrameCodec
from ktcs_bench.codec.profile import FrameProfile, load_profiles

from .harness import assert_agree, decoded, dissected, make_dissector, tshark_json, write_pcapng

SERIAL = """\
protocol: type1
crc_algorithms:
  crc-16/xmodem: {poly: 0x11021, reflect: false, init: 0x0000, xor_out: 0x0000, check: 0x31C3}
  crc-32: {poly: 0x104C11DB7, reflect: true, init: 0, xor_out: 0xFFFFFFFF, check: 0xCBF43926}
profiles:
  acme-serial:
    description: no ETX, SEQ first, big-endian, CRC-16/XMODEM over LEN..DATA and a pad byte
    stx: 0x7E
    etx: null
    byte_order: big
    header: [{name: seq, size: 2}, {name: len, size: 1}, {name: op, size: 1}]
    length_counts: [op, data]
    max_len: 200
    crc: {algorithm: crc-16/xmodem, covers: [len, data], size: 2, pad: 1}
  acme-serial-32:
    description: CRC-32 over STX..DATA, ETX 0x7F
    stx: 0x7E
    etx: 0x7F
    byte_order: little
    header: [{name: len, size: 2}, {name: seq, size: 1}, {name: op, size: 1}]
    length_counts: [data]
    max_len: 300
    crc: {algorithm: crc-32, covers: [stx, data], size: 4, pad: 0}
opcodes:
  - {op: 0x10, name: ZONE_REPORT, items: [{name: code, type: u32}, {name: state, type: u8}]}
  - {op: 0x20, name: POLL, fields: [{name: zone, type: u16}, {name: depth, type: u8}]}
  - {op: 0x30, name: SNAPSHOT, statuses: true}
  - {op: 0x06, name: ACK, control: true}
  - {op: 0x15, name: NAK, control: true, fields: [{name: reason, type: u8}]}
nak_reasons: {1: bad crc, 9: vendor busy}
"""

NETWORK = """\
protocol: type2
crc_algorithms:
  crc-16/arc: {poly: 0x18005, reflect: true, init: 0, xor_out: 0, check: 0xBB3D}
profiles:
  acme-net:
    description: STX 0x55, a 2-byte big-endian LEN, CRC over LEN..DATA
    stx: 0x55
    etx: null
    byte_order: big
    header: [{name: len, size: 2}, {name: seq, size: 1}, {name: op, size: 1}, {name: sub, size: 1}]
    length_counts: [data]
    max_len: 600
    crc: {algorithm: crc-16/arc, covers: [len, data], size: 2, pad: 0}
opcodes:
  - {op: 0x50, name: TELEGRAM, subs: {0: plain, 7: urgent}, items: [{name: code, type: u16}, {name: value, type: u16}]}
  - {op: 0x60, name: STATUS, subs: {0: ok, 1: degraded}, fields: [{name: uptime, type: u32}]}
  - {op: 0x15, name: NAK, control: true, subs: {1: crc error}, fields: [{name: refused_seq, type: u8}]}
nak_reasons: {1: crc error}
"""


def traffic(profile: FrameProfile, rng: random.Random) -> bytes:
    """Frames of every opcode, some corrupted or cut, garbage between, one cut off at the end."""
    codec = FrameCodec(profile)
    out = bytearray()
    for k in range(60):
        opcode = rng.choice(list(profile.opcodes.by_op.values()))
        values: dict[str, object] = {
            f.name: rng.randrange(1 << (8 * f.size)) for f in opcode.fields
        }
        if opcode.items:
            values["items"] = [
                [rng.randrange(1 << (8 * f.size)) for f in opcode.items]
                for _ in range(rng.randint(0, 3))
            ]
        if opcode.statuses:
            values["statuses"] = [rng.randrange(4) for _ in range(rng.randint(0, 9))]
        sub = rng.choice(list(opcode.subs) or [0]) if profile.has_sub else None
        frame = bytearray(codec.encode_message(k, opcode.name, sub, **values))
        if k % 9 == 4:
            frame[rng.randrange(1, len(frame))] ^= 0x10  # a bit error
        if k % 13 == 6:
            out += bytes([profile.stx, 0xFF]) + rng.randbytes(3)  # garbage, a false STX in it
        out += frame
    return bytes(out) + codec.encode_message(60, opcode.name, sub, **values)[:5]


def test_profiles_added_as_yaml_only_are_dissected(tmp_path: Path) -> None:
    vendor = tmp_path / "vendor"
    vendor.mkdir()
    (vendor / "acme-serial.yaml").write_text(SERIAL)
    (vendor / "acme-net.yaml").write_text(NETWORK)
    lua = make_dissector(
        tmp_path / "ktcs.lua",
        "--profile", str(vendor / "acme-serial.yaml"),
        "--profile", f"{vendor / 'acme-net.yaml'}:acme-net",
    )  # fmt: skip
    rng = random.Random(17)
    for path, name in (
        (vendor / "acme-serial.yaml", "acme-serial"),
        (vendor / "acme-serial.yaml", "acme-serial-32"),
        (vendor / "acme-net.yaml", "acme-net"),
    ):
        profile = load_profiles(path)[name]
        link = profile.protocol
        directions = ("a>b", "b>a") if link == "type1" else ("ixl>ctc", "ctc>ixl")
        data = {d: traffic(profile, rng) for d in directions}
        packets: list[CaptureRecord] = []
        for d in directions:  # packets of random sizes: frames split and several in one
            pos, t = 0, 1.0 + rng.random()
            while pos < len(data[d]):
                n = rng.choice([2, 7, 30, 100])
                packets.append(CaptureRecord(t, d, data[d][pos : pos + n]))
                pos, t = pos + n, t + 0.001
        cap = write_pcapng(
            tmp_path / f"{name}.pcapng", sorted(packets, key=lambda r: r.time or 0), link
        )
        short = "ktcs1" if link == "type1" else "ktcs2"
        args = ["-o", f"{short}.profile:{name}"] + (
            ["-d", "tcp.port==5020,ktcs2"] if link == "type2" else []
        )
        got = dissected(tshark_json(lua, cap, *args), short)
        want = {d: decoded(data[d], f"{path}:{name}") for d in directions}
        kinds = {r.get("error") for recs in want.values() for r in recs}
        assert {None, "crc", "truncated"} <= kinds, kinds  # good, corrupted and cut frames
        assert any(r.get("items") for recs in want.values() for r in recs)
        assert_agree(got, want)
