"""Seed 004 Fig. 7 as captured: the request checks under ktcs-type1-fig7, the reply is truncated."""

import json
import subprocess
import sys
from pathlib import Path

from ktcs_bench.codec import Frame, StreamDecoder, get_profile
from ktcs_bench.codec.hextext import parse_hex_text

ROOT = Path(__file__).resolve().parents[2]
CAPTURE = ROOT / "protocols" / "captures" / "fig7.hex"


def _records(profile_name: str) -> list:  # type: ignore[type-arg]
    data = parse_hex_text(CAPTURE.read_text(encoding="utf-8")).data
    dec = StreamDecoder(get_profile(profile_name))
    return dec.feed(data) + dec.close()


def test_capture_holds_both_frames_as_printed() -> None:
    text = parse_hex_text(CAPTURE.read_text(encoding="utf-8"))
    assert [len(c.data) for c in text.chunks] == [11, 121]
    assert [c.direction for c in text.chunks] == ["rx", "tx"]
    assert len(text.skipped_lines) == 2  # "Packet = ..." and "RequestAllInfo..." annotations


def test_fig7_profile_request_good_reply_truncated() -> None:
    request, reply = _records("ktcs-type1-fig7")
    assert isinstance(request, Frame) and request.error is None
    assert (request.seq, request.op, request.data) == (0x10, 0x0000, b"\x00\x84")
    assert request.crc_packet == request.crc_calc == 0xE7F1
    opcode = get_profile("ktcs-type1-fig7").opcodes.get(0)
    assert opcode is not None and opcode.parse(request.data) == {"start": 0, "count": 132}
    assert isinstance(reply, Frame) and reply.error == "truncated"
    assert (reply.seq, reply.op, reply.offset, len(reply.raw)) == (0x11, 0x0001, 11, 121)


def test_default_profile_reports_crc_error_on_the_request() -> None:
    first = _records("ktcs-type1")[0]
    assert isinstance(first, Frame)
    assert first.error == "crc" and not first.crc_ok
    assert first.offset == 0


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args],
        capture_output=True, text=True, timeout=60, cwd=ROOT,
    )  # fmt: skip


def test_cli_profile_auto_names_fig7_profile() -> None:
    out = _cli("decode", str(CAPTURE), "--profile", "auto")
    assert "profile auto: CRC checks ktcs-type1-fig7" in out.stdout
    assert "Packet = [F1]-[E7], Cal = [F1]-[E7]" in out.stdout
    assert "ERROR: truncated" in out.stdout
    assert out.returncode == 1  # the reply fails a check: truncated


def test_cli_json_lines_have_exactly_the_spec_keys() -> None:
    out = _cli("decode", str(CAPTURE), "--profile", "auto", "--json")
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    keys = {"protocol", "profile", "offset", "seq", "op", "op_name", "sub", "data", "items",
            "crc_ok", "crc_packet", "crc_calc", "error"}  # fmt: skip
    assert [set(r) for r in rows] == [keys, keys]
    assert rows[0]["profile"] == "ktcs-type1-fig7" and rows[0]["crc_ok"] is True
    assert rows[0]["op_name"] == "REQUEST_ALL" and rows[0]["error"] is None
    assert rows[1]["error"] == "truncated" and rows[1]["offset"] == 11


def test_cli_default_profile_reports_crc_error() -> None:
    out = _cli("decode", str(CAPTURE), "--profile", "ktcs-type1", "--json")
    first = json.loads(out.stdout.splitlines()[0])
    assert first["error"] == "crc" and first["crc_ok"] is False
    assert out.returncode == 1
