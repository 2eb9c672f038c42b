"""tshark with the generated dissector against `ktcs-bench decode --json`, frame by frame, on
captures of real links: two Type I links over real ptys and a Type II IXL/CTC session over real
TCP, each through a tap that corrupts the traffic and writes pcapng with the bench's writer; the
same byte streams cut into packets anew (several frames in one packet, frames over several); and
the seed 004 Fig. 7 capture under its own profile. 100 % agreement, error frames and garbage
included, and the ARQ links point where they should."""

from __future__ import annotations

import asyncio
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ktcs_bench.capture import CaptureRecord, open_writer, read_capture
from ktcs_bench.codec.frame import FrameCodec
from ktcs_bench.codec.profile import get_profile
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.datafiles import data_dir
from ktcs_bench.faults import BitErrors, CorruptFrame, InsertGarbage
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.transport.aio import LinkRunner
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.transport.ixl_client import IxlClient, StateTable
from ktcs_bench.transport.serialport import SerialTransport
from ktcs_bench.type1 import LinkConfig, LinkUp, Type1Link

from .harness import (
    Rec,
    assert_agree,
    decoded,
    dissected,
    streams,
    tshark_json,
    write_pcapng,
)

T1 = get_profile("ktcs-type1")
T2 = get_profile("ktcs-type2")
# unpaced ptys; the timers of a 96,000 bit/s line carrying short frames
FAST_LINE = LinkConfig(line_rate=96_000, longest_frame_data=64)


def rechunked(records: list[CaptureRecord], seed: int) -> list[CaptureRecord]:
    """The capture's byte streams cut into packets anew at random places; a packet is stamped
    with the time its last byte was recorded, so the directions interleave as on the wire."""
    rng = random.Random(seed)
    out: list[CaptureRecord] = []
    for direction in dict.fromkeys(r.direction for r in records):
        mine = [r for r in records if r.direction == direction]
        ends, total = [], 0
        for r in mine:
            total += len(r.data)
            ends.append(total)
        data = b"".join(r.data for r in mine)
        pos, k = 0, 0
        while pos < len(data):
            n = rng.choice([1, 3, 5, 9, 17, 40, 90, 300])
            stop = min(pos + n, len(data))
            while ends[k] < stop:
                k += 1
            out.append(CaptureRecord(mine[k].time, direction, data[pos:stop]))
            pos = stop
    return sorted(out, key=lambda r: r.time or 0.0)


def python_view(records: list[CaptureRecord], profile: str) -> dict[str, list[Rec]]:
    return {d: decoded(data, profile) for d, data in streams(records).items()}


def layers_of(packets: list[Any], short: str) -> list[tuple[int, str, dict[str, Any]]]:
    """(frame number, direction, protocol tree) for every record tshark shows."""
    out = []
    for p in packets:
        layers = p["_source"]["layers"]
        trees = layers.get(short, [])
        for t in trees if isinstance(trees, list) else [trees]:
            if f"{short}.offset" in t:
                out.append(
                    (
                        int(layers["frame"]["frame.number"]),
                        layers["pkt_comment"]["frame.comment"],
                        t,
                    )
                )
    return out


def check_arq(packets: list[Any], short: str) -> dict[str, int]:
    """Every ARQ link points at a frame of the right direction and SEQ; returns how many."""
    trees = layers_of(packets, short)
    by_frame: dict[int, list[tuple[str, dict[str, Any]]]] = {}
    for num, direction, t in trees:
        by_frame.setdefault(num, []).append((direction, t))
    x = short + "."

    def targets(num: int) -> list[tuple[str, dict[str, Any]]]:
        return by_frame.get(num, [])

    counts = {"ack": 0, "nak": 0, "retransmission": 0}
    for _num, direction, t in trees:
        if x + "arq.ack_to" in t:
            counts["ack"] += 1
            assert any(
                d != direction
                and u.get(x + "seq") == t[x + "seq"]
                and u.get(x + "op_name") not in ("ACK", "NAK")
                for d, u in targets(int(t[x + "arq.ack_to"]))
            ), t
        if x + "arq.nak_to" in t:
            counts["nak"] += 1
            refused = t.get(x + "nak.refused_seq", t[x + "seq"])
            assert any(
                d != direction and u.get(x + "seq") == refused
                for d, u in targets(int(t[x + "arq.nak_to"]))
            ), t
        if x + "arq.retransmission_of" in t:
            counts["retransmission"] += 1
            # the first transmission: the same bytes, or a bad frame the peer NAKed
            assert any(
                d == direction
                and u.get(x + "seq") == t[x + "seq"]
                and (u.get(x + "data") == t.get(x + "data") or x + "arq.naked_in" in u)
                for d, u in targets(int(t[x + "arq.retransmission_of"]))
            ), t
    return counts


def resent_after_nak(packets: list[Any], short: str) -> set[tuple[str, str]]:
    """(direction, error) of the bad frames the peer NAKed whose retransmission is linked to them."""
    x = short + "."
    trees = layers_of(packets, short)
    naked = {
        (num, d): t[x + "error"]
        for num, d, t in trees
        if x + "error" in t and x + "arq.naked_in" in t
    }
    return {
        (d, naked[key])
        for _, d, t in trees
        if (key := (int(t.get(x + "arq.retransmission_of", 0)), d)) in naked
    }


def errors_in(view: dict[str, list[Rec]]) -> set[str]:
    kinds = {r["error"] for recs in view.values() for r in recs if r.get("error")}
    if any("garbage" in r for recs in view.values() for r in recs):
        kinds.add("garbage")
    return kinds


# -- Type I ------------------------------------------------------------------------------------


def type1_session(path: Path) -> None:
    """Two Type I links on real ptys through a tap writing pcapng: start-up (REQUEST_ALL and
    ALL_INFO both ways), CHANGE traffic, bit errors (CRC errors, NAKs, retransmissions), garbage
    with false STX bytes, a frame with a bad ETX, one with LEN over the maximum, and a frame cut
    off by the end of the capture."""
    codec = FrameCodec(T1)
    writer = open_writer(path, link="type1")
    tap = PtyTap(names=("ixl", "atc"), profile=T1, seed=5, control=None, writers=[writer])
    tap.start()
    state = {"ixl": bytes(range(1, 13)), "atc": bytes([1, 0] * 10)}

    def provider(end: str) -> Callable[[int, int], bytes]:
        return lambda start, count: state[end][start : start + count]

    async def main() -> None:
        links = {
            end: Type1Link(T1, FAST_LINE, end, state_provider=provider(end))
            for end in ("ixl", "atc")
        }
        transports = {end: SerialTransport(tap.paths[end], end, None) for end in ("ixl", "atc")}
        runners = {end: LinkRunner(links[end], transports[end]) for end in ("ixl", "atc")}
        tasks = [asyncio.ensure_future(r.run()) for r in runners.values()]
        try:
            for r in runners.values():
                await r.next_event(LinkUp, timeout=10)

            async def exchange(rounds: int) -> None:
                for k in range(rounds):
                    for end in ("ixl", "atc"):
                        runners[end].send(
                            links[end].message("CHANGE", items=[[k + 1, k % 3], [300 + k, 1]])
                        )
                    while any(link.queued for link in links.values()):
                        await asyncio.sleep(0.005)

            await exchange(5)
            tap.inject(BitErrors(4e-3))  # CRC errors: NAK, retransmission
            await exchange(25)
            tap.clear()
            # the same in every run, whatever the bit errors hit: the next frame each way has a
            # LEN over the maximum (the ixl's) or a bad CRC (the atc's); the peer NAKs it, the
            # sender resends it
            for end, fault in (
                ("ixl", CorruptFrame(2, 0x08, direction="ixl>atc")),  # LEN's high byte: +2048
                ("atc", CorruptFrame(5, 0x01, direction="atc>ixl")),  # a DATA byte
            ):
                tap.inject(fault)
                runners[end].send(links[end].message("CHANGE", items=[[99, 1]]))
                while links[end].queued:
                    await asyncio.sleep(0.005)
            tap.inject(
                InsertGarbage(bytes([0x02, 0x40, 0x00]) + b"\x99\x02\x13", direction="ixl>atc")
            )
            await exchange(3)
            bad_etx = bytearray(codec.encode(0x70, 2, bytes([5, 0, 1])))
            bad_etx[-1] = 0x04
            tap.send("ixl>atc", bytes(bad_etx))
            too_long = bytearray(codec.encode(0x71, 2, bytes([5, 0, 1])))
            too_long[1:3] = (2000).to_bytes(2, "little")  # LEN over the maximum (1024)
            tap.send("atc>ixl", bytes(too_long))
            await exchange(3)
            for r in runners.values():
                r.stop()
            await asyncio.gather(*tasks, return_exceptions=True)
            tap.send("ixl>atc", codec.encode(0x72, 2, bytes([9, 0, 1]))[:8])  # cut off by the end
            await asyncio.sleep(0.1)
        finally:
            for r in runners.values():
                r.stop()
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            try:
                tap.stop()
            finally:
                for t in transports.values():
                    t.close()

    asyncio.run(main())


def test_type1_link_on_real_ptys_through_a_tap(lua: Path, tmp_path: Path) -> None:
    cap = tmp_path / "st-ixl-atc.pcapng"
    type1_session(cap)
    records = read_capture(cap).records
    python = python_view(records, "ktcs-type1")
    assert {"crc", "etx", "length", "truncated", "garbage"} <= errors_in(python), errors_in(python)
    packets = tshark_json(lua, cap)
    assert_agree(dissected(packets, "ktcs1"), python)
    arq = check_arq(packets, "ktcs1")
    assert arq["ack"] > 30 and arq["nak"] >= 1 and arq["retransmission"] >= 1, arq
    assert {("ixl>atc", "length"), ("atc>ixl", "crc")} <= resent_after_nak(packets, "ktcs1")
    # the same bytes in other packets: several frames in one, one frame over several
    again = write_pcapng(tmp_path / "rechunked.pcapng", rechunked(records, 1), "type1")
    packets = tshark_json(lua, again)
    assert_agree(dissected(packets, "ktcs1"), python)
    trees = layers_of(packets, "ktcs1")
    per_packet = [num for num, _, _ in trees]
    assert max(per_packet.count(n) for n in set(per_packet)) >= 3  # several records in one packet
    assert sum("ktcs1.first_in" in t for _, _, t in trees) > 10  # records over several packets
    assert check_arq(packets, "ktcs1")["ack"] > 30


# -- Type II -----------------------------------------------------------------------------------


def type2_session(path: Path) -> None:
    """An IXL and the CTC over real TCP through a tap writing pcapng: IDENT, the full state in
    parts, indications, controls and their results, bit errors (NAKs, retransmissions), garbage,
    a frame with LEN over the maximum and a frame cut off by the end of the capture."""
    codec = FrameCodec(T2)
    writer = open_writer(path, link="type2")

    async def main() -> None:
        app = StateTable(
            {code: code % 4 for code in range(1, 101)},
            control=lambda c, v: (c % 2 == 0, 0 if c % 2 == 0 else 2),
        )
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            tap = TcpTap(
                ("127.0.0.1", 0),
                ("127.0.0.1", ctc.port),
                names=("ixl", "ctc"),
                control=None,
                writers=[writer],
            )
            tap.start()
            try:
                assert tap.listen_address is not None
                async with IxlClient(
                    20,
                    "127.0.0.1",
                    tap.listen_address[1],
                    app,
                    backoff_initial=0.05,
                    backoff_max=0.2,
                ) as ixl:
                    await ctc.wait_until(lambda: tables.stations[20].synced)
                    for k in range(6):
                        app.state[k + 1] = (app.state[k + 1] + 1) % 4
                        ixl.indicate([(k + 1, app.state[k + 1])])
                        await ctc.control(20, 10 + k)
                    tap.inject(BitErrors(1e-3))  # a few bad frames (12 in 10 s get us dropped)
                    for k in range(30):
                        app.state[k + 1] = (app.state[k + 1] + 1) % 4
                        ixl.indicate([(k + 1, app.state[k + 1]), (k + 50, 1)])
                        await asyncio.sleep(0.01)
                    tap.clear()
                    await asyncio.sleep(0.3)
                    await ctc.wait_until(lambda: tables.stations[20].synced, timeout=20)
                    tap.send("ixl>ctc", b"\x17\x02\x99")  # garbage with a false STX
                    too_long = bytearray(codec.encode(0x33, 0x10, bytes([7, 0, 1]), 0))
                    too_long[1] = 200  # LEN over the maximum (124)
                    tap.send("ixl>ctc", bytes(too_long))
                    await ctc.control(20, 42)
                    await asyncio.sleep(0.2)
                    tap.send("ctc>ixl", codec.encode(0x34, 0x20, bytes([9, 0, 1]), 0)[:6])
                    await asyncio.sleep(0.05)
            finally:
                tap.stop()

    asyncio.run(main())


def test_type2_session_over_real_tcp_through_a_tap(lua: Path, tmp_path: Path) -> None:
    cap = tmp_path / "st20-ctc.pcapng"
    type2_session(cap)
    records = read_capture(cap).records
    python = python_view(records, "ktcs-type2")
    assert {"crc", "length", "truncated", "garbage"} <= errors_in(python), errors_in(python)
    # found by the heuristic (the IXL's first segment starts with its IDENT)
    packets = tshark_json(lua, cap)
    assert_agree(dissected(packets, "ktcs2"), python)
    arq = check_arq(packets, "ktcs2")
    assert arq["nak"] >= 1 and arq["retransmission"] >= 1, arq
    # other packets: TCP reassembles frames split over segments; and with TCP reassembly off
    again = write_pcapng(tmp_path / "rechunked.pcapng", rechunked(records, 2), "type2")
    for extra in ([], ["-o", "tcp.desegment_tcp_streams:FALSE"]):
        packets = tshark_json(lua, again, "-d", "tcp.port==5020,ktcs2", *extra)
        assert_agree(dissected(packets, "ktcs2"), python)
    reassembled = tshark_json(lua, again, "-d", "tcp.port==5020,ktcs2")
    assert any("tcp.reassembled_in" in p["_source"]["layers"].get("tcp", {}) for p in reassembled)


# -- Fig. 7 ------------------------------------------------------------------------------------


def test_fig7_capture_under_its_profile_by_preference(lua: Path, tmp_path: Path) -> None:
    """The paper's capture: the request's CRC checks under ktcs-type1-fig7, the reply is cut
    short (121 of the bytes its LEN announces survived the transcription)."""
    records = read_capture(data_dir("protocols") / "captures" / "fig7.hex").records
    stamped = [CaptureRecord(1.0 + k, r.direction, r.data) for k, r in enumerate(records)]
    cap = write_pcapng(tmp_path / "fig7.pcapng", stamped, "type1")
    python = python_view(stamped, "ktcs-type1-fig7")
    packets = tshark_json(lua, cap, "-o", "ktcs1.profile:ktcs-type1-fig7")
    got = dissected(packets, "ktcs1")
    assert_agree(got, python)
    frames = [r for recs in got.values() for r in recs]
    assert [(f["seq"], f["op"], f["crc_ok"], f["error"]) for f in frames] == [
        (0x10, 0, True, None),
        (0x11, 1, False, "truncated"),
    ]
    # under the default profile (no preference) the same capture does not check
    default = dissected(tshark_json(lua, cap), "ktcs1")
    assert default == python_view(stamped, "ktcs-type1")
    assert not any(r.get("crc_ok") for recs in default.values() for r in recs)
