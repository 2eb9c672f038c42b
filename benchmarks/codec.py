"""SPEC §8 codec figures, measured in one run as ratios to a floor timed in the same run.

1. encode + decode + CRC of 132-byte Type I frames (ALL_INFO of 132 codes) with the bench's codec
   (FrameCodec.encode, StreamDecoder.feed one frame at a time), against the floor: the same work
   with a hand-written struct + crcmod encoder and parser for exactly this layout. Goal <= 3x.
2. Bulk decoding throughput, goal >= 20 MB/s, on a generated capture of the frames a Type I link
   carries (ALL_INFO of 132 codes, CHANGE of 5 items, ACK, LINK_TEST, in equal numbers, with 1 %
   garbage between them), two ways:
   a. a 100 MB binary stream, as the serial line carries it, fed to the decoder in 1 MiB chunks;
   b. a 100 MB capture file in the bench's hex-log form (`<seconds> <direction> <hex>`, one frame
      a line, as taps write it), read by the same parser and decoder `ktcs-bench decode` uses.
   Beside each, the floor: a minimal struct+crcmod loop over the same bytes (framing by LEN, CRC
   and ETX checked, no resynchronisation, no records), so the ratio is machine-independent.

Run: python benchmarks/codec.py [--mb 100] [--frames 200000]
"""

from __future__ import annotations

import argparse
import platform
import random
import statistics
import struct
import time

from ktcs_bench.codec import Frame, FrameCodec, StreamDecoder, get_profile
from ktcs_bench.codec.crc import crc16_arc, crc_extension_in_use
from ktcs_bench.codec.hextext import parse_hex_text


def bench_roundtrip(n: int) -> tuple[float, float]:
    profile = get_profile("ktcs-type1")
    codec = FrameCodec(profile)
    payloads = [bytes(random.Random(k).randrange(2) for _ in range(132)) for k in range(64)]
    op = profile.opcodes.by_name["ALL_INFO"].op

    head = struct.Struct("<BHBH")
    tail = struct.Struct("<HHB")

    def floor_once(seq: int, data: bytes) -> None:
        body = head.pack(2, len(data), seq, op) + data
        wire = body + tail.pack(crc16_arc(body), 0, 3)
        _, length, s, o = head.unpack_from(wire)
        end = 6 + length
        ok = crc16_arc(memoryview(wire)[:end]) == struct.unpack_from("<H", wire, end)[0]
        assert ok and wire[end + 4] == 3 and s == seq and wire[6:end] == data

    dec = StreamDecoder(profile)

    def ours_once(seq: int, data: bytes) -> None:
        wire = codec.encode(seq, op, data)
        (frame,) = dec.feed(wire)
        assert frame.error is None and frame.seq == seq and frame.data == data  # type: ignore[union-attr]

    def timed(fn) -> float:  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        for k in range(n):
            fn(k & 0xFF, payloads[k & 63])
        return (time.perf_counter() - t0) / n

    floor, ours = [], []
    for _ in range(5):  # interleaved, so both see the same machine state
        floor.append(timed(floor_once))
        ours.append(timed(ours_once))
    return statistics.median(floor), statistics.median(ours)


def generate_capture(mb: float, seed: int = 7) -> bytes:
    profile = get_profile("ktcs-type1")
    codec = FrameCodec(profile)
    rng = random.Random(seed)
    samples = [
        codec.encode_message(1, "ALL_INFO", statuses=[rng.randrange(2) for _ in range(132)]),
        codec.encode_message(2, "CHANGE", items=[[rng.randrange(400), 1] for _ in range(5)]),
        codec.encode(3, profile.opcodes.by_name["ACK"].op),
        codec.encode(4, profile.opcodes.by_name["LINK_TEST"].op),
    ]
    block = bytearray()
    while len(block) < 1 << 20:
        if rng.random() < 0.01:
            block += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 20)))
        block += rng.choice(samples)
    reps = max(1, int(mb * (1 << 20) / len(block)))
    return bytes(block) * reps


def bench_bulk(data: bytes) -> tuple[float, int]:
    dec = StreamDecoder(get_profile("ktcs-type1"))
    frames = 0
    chunk = 1 << 20
    t0 = time.perf_counter()
    for i in range(0, len(data), chunk):
        for rec in dec.feed(data[i : i + chunk]):
            if isinstance(rec, Frame) and rec.error is None:
                frames += 1
    dec.close()
    return time.perf_counter() - t0, frames


def bench_bulk_floor(data: bytes) -> float:
    head = struct.Struct("<HBH").unpack_from
    t0 = time.perf_counter()
    i, n, frames = 0, len(data), 0
    mv = memoryview(data)
    while i < n:
        if data[i] != 2:
            i += 1
            continue
        if n - i < 6:
            break
        length = head(data, i + 1)[0]
        end = i + 6 + length
        if length > 1024 or end + 5 > n or data[end + 4] != 3:
            i += 1
            continue
        if crc16_arc(mv[i:end]) == data[end] | data[end + 1] << 8:
            frames += 1
            i = end + 5
        else:
            i += 1
    return time.perf_counter() - t0


def hexlog_text(data: bytes) -> str:
    """The capture as a hex log: one frame (or garbage span) a line, as a tap writes it."""
    dec = StreamDecoder(get_profile("ktcs-type1"))
    lines = [
        f"{k * 0.001:.6f} ixl>atc {rec.raw.hex(' ')}"
        for k, rec in enumerate(dec.feed(data) + dec.close())
    ]
    return "\n".join(lines) + "\n"


def bench_hexlog(text: str) -> tuple[float, int]:
    t0 = time.perf_counter()
    parsed = parse_hex_text(text)
    dec = StreamDecoder(get_profile("ktcs-type1"))
    records = dec.feed(parsed.data) + dec.close()
    frames = sum(1 for r in records if isinstance(r, Frame) and r.error is None)
    return time.perf_counter() - t0, frames


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--mb", type=float, default=100.0, help="size of the generated capture")
    ap.add_argument("--frames", type=int, default=100_000, help="frames per round-trip sample")
    args = ap.parse_args()
    print(f"python {platform.python_version()} on {platform.machine()}; "
          f"crcmod C extension in use: {crc_extension_in_use()}")  # fmt: skip
    floor, ours = bench_roundtrip(args.frames)
    ratio = ours / floor
    print(f"encode+decode+CRC, 132-byte Type I frame: floor (struct+crcmod) {floor * 1e6:.2f} us, "
          f"ktcs-bench {ours * 1e6:.2f} us -> {ratio:.2f}x  (goal <= 3x: "
          f"{'met' if ratio <= 3 else 'NOT met'})")  # fmt: skip
    data = generate_capture(args.mb)
    seconds, frames = bench_bulk(data)
    floor_s = bench_bulk_floor(data)
    rate = len(data) / seconds / 1e6
    print(f"bulk decode, binary stream: {len(data) / 1e6:.1f} MB, {frames} frames in {seconds:.2f} s"
          f" -> {rate:.1f} MB/s (floor loop {len(data) / floor_s / 1e6:.1f} MB/s, ratio "
          f"{seconds / floor_s:.2f}x)  (goal >= 20 MB/s: {'met' if rate >= 20 else 'NOT met'})")  # fmt: skip
    text = hexlog_text(data[: int(len(data) * 100 / 330)])  # hex log of about the same size in MB
    seconds, frames = bench_hexlog(text)
    size = len(text.encode())
    rate = size / seconds / 1e6
    print(f"bulk decode, hex-log capture file: {size / 1e6:.1f} MB, {frames} frames in {seconds:.2f} s"
          f" -> {rate:.1f} MB/s  (goal >= 20 MB/s: {'met' if rate >= 20 else 'NOT met'})")  # fmt: skip


if __name__ == "__main__":
    main()
