"""Hex log and pcapng: round trips, `decode` reads a log, tshark reads our pcapng."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.capture import CaptureRecord, open_writer, read_capture
from ktcs_bench.capture.hexlog import format_line, parse_hex_log
from ktcs_bench.capture.pcapng import PcapngEncoder, _checksum, parse_pcapng
from ktcs_bench.codec import FrameCodec, get_profile

T0 = 1_712_345_678.125
REQ = bytes.fromhex("02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03")
ACK = bytes.fromhex("02 00 00 10 06 00 03 87 00 00 03")
IDENT = bytes.fromhex("02 06 00 01 00 14 00 01 5B DD")
HEARTBEAT = bytes.fromhex("02 03 02 40 00 E9 84")

TYPE1 = [
    CaptureRecord(T0, "ixl>atc", REQ),
    CaptureRecord(T0 + 0.020125, "atc>ixl", ACK),
    CaptureRecord(T0 + 1.5, "ixl>atc", FrameCodec(get_profile("ktcs-type1")).encode(0x11, 3)),
]
TYPE2 = [CaptureRecord(T0, "ixl>ctc", IDENT), CaptureRecord(T0 + 0.25, "ctc>ixl", HEARTBEAT)]


def _same(a: list[CaptureRecord], b: list[CaptureRecord]) -> None:
    assert [(r.direction, r.data) for r in a] == [(r.direction, r.data) for r in b]
    for x, y in zip(a, b, strict=True):
        assert x.time is not None and y.time is not None
        assert abs(x.time - y.time) < 2e-6


def tshark() -> str:
    path = shutil.which("tshark")
    if path is None:
        pytest.fail(
            "tshark is not installed: the pcapng tests need it "
            "(Debian: apt-get install -y tshark) -- they must not be skipped"
        )
    return path


def test_hex_log_line_shape() -> None:
    line = format_line(CaptureRecord(T0 + 0.5, "ixl>atc", ACK), start=T0)
    assert line == "0.500000 ixl>atc 02 00 00 10 06 00 03 87 00 00 03\n"


@pytest.mark.parametrize("suffix", [".hex", ".pcapng"])
def test_round_trip_type1(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"cap{suffix}"
    with open_writer(path, link="type1", profile="ktcs-type1") as w:
        for r in TYPE1:
            w.write(r)
    cap = read_capture(path)
    _same(cap.records, TYPE1)
    assert cap.directions == ["ixl>atc", "atc>ixl"]


def test_round_trip_type2_pcapng_strips_ip_tcp(tmp_path: Path) -> None:
    path = tmp_path / "t2.pcapng"
    with open_writer(path, link="type2", endpoints={"ctc": ("127.0.0.1", 5020)}) as w:
        for r in TYPE2:
            w.write(r)
    _same(read_capture(path).records, TYPE2)


def test_hex_log_reads_console_text_too() -> None:
    log = parse_hex_log("수신 = <02><00><00><10><06><00><03><87><00><00><03>\nPacket = x\n")
    assert [(r.direction, r.data, r.time) for r in log.records] == [("rx", ACK, None)]


def test_decode_reads_a_hex_log(tmp_path: Path) -> None:
    path = tmp_path / "cap.hex"
    with open_writer(path, profile="ktcs-type1") as w:
        for r in TYPE1:
            w.write(r)
    out = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "decode", str(path), "--profile",
         "ktcs-type1"], capture_output=True, text=True, timeout=30,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "3 frames, 3 good" in out.stdout
    assert "t=1.500000 ixl>atc" in out.stdout
    assert "REQUEST_ALL" in out.stdout and "ACK" in out.stdout and "LINK_TEST" in out.stdout


def test_pcapng_encoder_is_pure_and_deterministic() -> None:
    a, b = PcapngEncoder("type1"), PcapngEncoder("type1")
    blob_a = a.start() + b"".join(a.encode(r) for r in TYPE1)
    blob_b = b.start() + b"".join(b.encode(r) for r in TYPE1)
    assert blob_a == blob_b
    _same(parse_pcapng(blob_a), TYPE1)


def _tshark_fields(path: Path, *fields: str) -> list[list[str]]:
    cmd = [tshark(), "-r", str(path), "-T", "fields"]
    for f in fields:
        cmd += ["-e", f]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return [line.split("\t") for line in out.stdout.splitlines() if line.strip()]


def test_tshark_reads_type1_pcapng(tmp_path: Path) -> None:
    path = tmp_path / "t1.pcapng"
    with open_writer(path, link="type1") as w:
        for r in TYPE1:
            w.write(r)
    rows = _tshark_fields(path, "frame.time_epoch", "frame.interface_name", "data.data")
    assert len(rows) == len(TYPE1)
    for row, rec in zip(rows, TYPE1, strict=True):
        assert rec.time is not None
        assert abs(float(row[0]) - rec.time) < 2e-6
        assert row[1] == rec.direction
        assert bytes.fromhex(row[2]) == rec.data


def test_tshark_reads_type2_pcapng_as_tcp(tmp_path: Path) -> None:
    path = tmp_path / "t2.pcapng"
    ends = {"ixl": ("127.0.0.1", 40123), "ctc": ("127.0.0.1", 5020)}
    with open_writer(path, link="type2", endpoints=ends) as w:
        for r in TYPE2:
            w.write(r)
    rows = _tshark_fields(
        path, "frame.time_epoch", "tcp.srcport", "tcp.dstport", "tcp.payload", "tcp.seq_raw"
    )
    assert len(rows) == 2
    assert [(r[1], r[2]) for r in rows] == [("40123", "5020"), ("5020", "40123")]
    for row, rec in zip(rows, TYPE2, strict=True):
        assert rec.time is not None
        assert abs(float(row[0]) - rec.time) < 2e-6
        assert bytes.fromhex(row[3]) == rec.data
    # checksums are valid when Wireshark is asked to verify them
    cmd = [tshark(), "-r", str(path), "-o", "tcp.check_checksum:TRUE", "-o",
           "ip.check_checksum:TRUE", "-Y", "tcp.checksum.status == 0 || ip.checksum.status == 0"]  # fmt: skip
    bad = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 0 and bad.stdout.strip() == "", bad.stdout


@settings(max_examples=500)
@given(
    data=st.binary(max_size=200)
    | st.lists(
        st.sampled_from([b"\xff\xff", b"\x00\x00", b"\x80\x00", b"\x7f\xff"]), max_size=40
    ).map(b"".join)
)
def test_the_internet_checksum_is_rfc_1071s_folded_word_sum(data: bytes) -> None:
    """`_checksum` takes the sum modulo 0xFFFF in one step; it must give what folding the sum
    of the 16-bit words gives, sums that are multiples of 0xFFFF (folded to 0xFFFF) included."""
    padded = data + b"\0" * (len(data) % 2)
    total = sum(int.from_bytes(padded[i : i + 2], "big") for i in range(0, len(padded), 2))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    assert _checksum(data) == ~total & 0xFFFF
