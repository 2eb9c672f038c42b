"""Expert info and the ARQ analysis on a capture whose every frame is known: the worked examples
of SPEC §3.6 with a bad CRC, a bad ETX, LEN over the maximum, garbage, a NAK and the frame sent
again, and a frame cut off by the end of the capture; and names from a code chart."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ktcs_bench.capture import CaptureRecord
from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.datafiles import data_dir

from .harness import make_dissector, run_tshark, tshark_json, write_pcapng

REQ = bytes.fromhex("02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03")
ACK_10 = bytes.fromhex("02 00 00 10 06 00 03 87 00 00 03")
NAK_11 = bytes.fromhex("02 01 00 11 15 00 01 F7 29 00 00 03")
CHANGE = bytes.fromhex("02 06 00 05 02 00 03 00 01 04 01 00 18 58 00 00 03")
ALL_INFO = bytes.fromhex("02 08 00 11 01 00 01 01 01 01 00 00 00 00 F0 6E 00 00 03")


def bad_crc(frame: bytes) -> bytes:
    return frame[:-5] + bytes([frame[-5] ^ 0xFF]) + frame[-4:]


CAPTURE = [
    ("ixl>atc", REQ),  # 1
    ("atc>ixl", ACK_10),  # 2: ACK of 1
    ("atc>ixl", bad_crc(ALL_INFO)),  # 3: CRC error
    ("ixl>atc", NAK_11),  # 4: NAK of 3
    ("atc>ixl", ALL_INFO),  # 5: sent again
    ("ixl>atc", ACK_10[:-1] + b"\x04"),  # 6: bad ETX
    ("ixl>atc", b"\x55\xaa"),  # 7: garbage
    ("ixl>atc", bytes.fromhex("02 00 08 12 03 00")),  # 8: LEN 2048, over 1024
    ("atc>ixl", CHANGE),  # 9
    ("ixl>atc", REQ[:7]),  # 10: cut off by the end of the capture
]


def experts(tree: dict[str, Any]) -> set[str]:
    found = tree.get("_ws.expert", [])
    return {
        k
        for e in (found if isinstance(found, list) else [found])
        for k in e
        if k.startswith("ktcs1.")
    }


def test_expert_info_and_arq_links(lua: Path, tmp_path: Path) -> None:
    records = [CaptureRecord(1.0 + k / 10, d, b) for k, (d, b) in enumerate(CAPTURE)]
    cap = write_pcapng(tmp_path / "experts.pcapng", records, "type1")
    packets = tshark_json(lua, cap)
    trees = {
        int(p["_source"]["layers"]["frame"]["frame.number"]): p["_source"]["layers"]["ktcs1"]
        for p in packets
    }
    x = "ktcs1."
    assert trees[1][x + "arq.acked_in"] == "2" and trees[2][x + "arq.ack_to"] == "1"
    assert trees[3][x + "error"] == "crc" and x + "expert.crc" in experts(trees[3])
    assert trees[3][x + "crc_ok"] == "0" and trees[3][x + "crc"] != trees[3][x + "crc_calc"]
    assert trees[4][x + "arq.nak_to"] == "3" and x + "expert.nak" in experts(trees[4])
    assert trees[3][x + "arq.naked_in"] == "4"
    assert trees[5][x + "arq.retransmission_of"] == "3" and trees[5][x + "arq.transmission"] == "2"
    assert x + "expert.retransmission" in experts(trees[5])
    assert trees[6][x + "error"] == "etx" and x + "expert.etx" in experts(trees[6])
    assert x + "garbage" in trees[7] and x + "expert.garbage" in experts(trees[7])
    assert trees[8][x + "error"] == "length" and x + "expert.length" in experts(trees[8])
    assert trees[9][x + "items"] == "2"
    assert trees[10][x + "error"] == "truncated" and x + "expert.truncated" in experts(trees[10])
    for good in (1, 2, 4, 5, 9):
        assert trees[good][x + "crc_ok"] == "1" and x + "error" not in trees[good]
    # the text a person reads: names of the NAK reason, the console's CRC words
    text = run_tshark(lua, cap, "-V").stdout
    assert "Bad CRC (the CRC does not check): Packet = [0F]-[6E], Cal = [F0]-[6E]" in text
    assert "reason: 1 (crc error)" in text
    assert "LEN 2048 is over the profile's maximum 1024" in text
    assert "Truncated: 7 bytes of the 15 its LEN announces" in text


def test_code_names_from_a_chart(tmp_path: Path) -> None:
    chart_file = data_dir("code_charts") / "st18_atc_to_ixl.yaml"
    chart = load_chart(chart_file)
    lua = make_dissector(tmp_path / "named.lua", "--chart", str(chart_file))
    cap = write_pcapng(
        tmp_path / "c.pcapng",
        [CaptureRecord(1.0, "atc>ixl", CHANGE), CaptureRecord(1.1, "atc>ixl", ALL_INFO)],
        "type1",
    )
    text = run_tshark(lua, cap, "-V").stdout
    assert f"code: 3 ({chart.name_of(3)})" in text
    assert f"Code 1 {chart.name_of(1)}: 1" in text
    assert "Lua Error" not in text


def test_type2_on_the_ports_of_its_preference(lua: Path, tmp_path: Path) -> None:
    """A stream picked up inside a frame: the heuristic cannot see it; the port preference can."""
    heartbeat = bytes.fromhex("02 03 02 40 00 E9 84")
    records = [
        CaptureRecord(1.0, "ctc>ixl", heartbeat[:3]),
        CaptureRecord(1.1, "ctc>ixl", heartbeat[3:]),
    ]
    cap = write_pcapng(tmp_path / "t2.pcapng", records, "type2")
    assert not any("ktcs2" in p["_source"]["layers"] for p in tshark_json(lua, cap))
    packets = tshark_json(lua, cap, "-o", "ktcs2.tcp_ports:5020")
    frame = packets[1]["_source"]["layers"]["ktcs2"]
    assert (frame["ktcs2.op_name"], frame["ktcs2.sub_name"], frame["ktcs2.crc_ok"]) == (
        "HEARTBEAT",
        "heartbeat",
        "1",
    )
