"""SPEC §8 codec figures, measured in one run as ratios to a floor timed in the same run.

1. encode + decode + CRC of 132-byte Type I frames (ALL_INFO of 132 codes) with the bench's codec
   (FrameCodec.encode, StreamDecoder.feed one frame at a time), against the floor: the same work
   with a hand-written struct + crcmod encoder and parser for exactly this layout. Goal <= 3x.
2. Bulk decoding throughput: a generated capture (default 100 MB: ALL_INFO, CHANGE, ACK, LINK_TEST
   frames with 1 % garbage between them) fed in 1 MiB chunks. Goal >= 20 MB/s.

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    rate = len(data) / seconds / 1e6
    print(f"bulk decode: {len(data) / 1e6:.1f} MB, {frames} frames in {seconds:.2f} s -> "
          f"{rate:.1f} MB/s  (goal >= 20 MB/s: {'met' if rate >= 20 else 'NOT met'})")  # fmt: skip


if __name__ == "__main__":
    main()
