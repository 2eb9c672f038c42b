"""`ktcs-bench decode` as a user runs it, against a plain script doing the same work, in one run.

1. `decode --json --profile ktcs-type1` on 100,000 well-formed CHANGE frames (one frame a line,
   spaced hex as `encode` prints it), against the floor: a plain script that does the same work
   for exactly this layout -- bytes.fromhex, framing with struct, CRC-16/ARC by crcmod, the items
   by struct.iter_unpack, one json.dumps per frame with the same keys (SPEC §7). Both run as
   subprocesses writing to a file, interleaved, so both pay Python's start-up and see the same
   machine state; the figure is the ratio of the medians. Goal <= 1.5x.
2. Peak memory (RSS) of `decode --json` and `decode --profile auto` on a generated hex-log
   capture of two sizes: it streams, so the peak does not grow with the input.
3. `decode --json --protocol type1` and `decode --profile auto` on corrupted input -- frames that
   all fail their CRC (`02 03 00 XX 02 00` and 8 random bytes a line), so every frame takes the
   resynchronising slow path and auto finds no profile whose CRC checks -- at several sizes: peak
   RSS, wall and CPU time, and CPU seconds per MB, which stay flat when the time is linear (the
   first 4 MiB decoded are decoded three times under auto: two profiles vote, the winner prints).

Run: python benchmarks/decode.py [--frames 100000] [--rounds 5] [--mb 10] [--corrupt 1,3,10,30]
     [--only ratio|memory|corrupted]
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ktcs_bench.codec import FrameCodec, get_profile

PLAIN = r"""
import json, struct, sys
import crcmod.predefined

crc = crcmod.predefined.mkCrcFun("crc-16")  # CRC-16/ARC
head = struct.Struct("<BHBH")
item = struct.Struct("<HB")
out = sys.stdout
with open(sys.argv[1], encoding="utf-8") as f:
    offset = 0
    for line in f:
        raw = bytes.fromhex(line)
        stx, length, seq, op = head.unpack_from(raw)
        end = 6 + length
        packet = raw[end] | raw[end + 1] << 8
        calc = crc(raw[:end])
        ok = stx == 2 and packet == calc and raw[end + 2 : end + 5] == b"\0\0\3"
        data = raw[6:end]
        out.write(json.dumps({
            "protocol": "type1", "profile": "ktcs-type1", "offset": offset, "seq": seq,
            "op": op, "op_name": "CHANGE", "sub": None, "data": data.hex(),
            "items": [list(t) for t in item.iter_unpack(data)], "crc_ok": ok,
            "crc_packet": packet, "crc_calc": calc, "error": None if ok else "crc",
        }, ensure_ascii=False, separators=(", ", ": ")) + "\n")
        offset += len(raw)
"""


def change_frames(n: int, seed: int = 5) -> str:
    """n well-formed CHANGE frames of 1-8 items, one a line, spaced hex as `encode` prints."""
    codec = FrameCodec(get_profile("ktcs-type1"))
    rng = random.Random(seed)
    lines = []
    for k in range(n):
        items = [[rng.randrange(1, 400), rng.randrange(4)] for _ in range(rng.randrange(1, 9))]
        lines.append(codec.encode_message(k & 0xFF, "CHANGE", items=items).hex(" ").upper())
    return "\n".join(lines) + "\n"


def run_timed(argv: list[str], out: Path) -> float:
    with out.open("wb") as sink:
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=sink, check=True)
        return time.perf_counter() - t0


def bench_json(frames: int, rounds: int, folder: Path) -> tuple[float, float]:
    capture = folder / "changes.hex"
    capture.write_text(change_frames(frames), encoding="utf-8")
    plain = folder / "plain.py"
    plain.write_text(PLAIN, encoding="utf-8")
    ours_argv = [sys.executable, "-m", "ktcs_bench.cli.main", "decode", "--json",
                 "--profile", "ktcs-type1", str(capture)]  # fmt: skip
    plain_argv = [sys.executable, str(plain), str(capture)]
    ours, floor = [], []
    for _ in range(rounds):
        floor.append(run_timed(plain_argv, folder / "plain.json"))
        ours.append(run_timed(ours_argv, folder / "ours.json"))
    got = (folder / "ours.json").read_text(encoding="utf-8")
    if got != (folder / "plain.json").read_text(encoding="utf-8"):
        raise SystemExit("decode --json and the plain script disagree: not the same work")
    return statistics.median(floor), statistics.median(ours)


def hexlog_capture(path: Path, mb: float) -> None:
    """A hex log of Type I traffic (ALL_INFO, CHANGE, ACK, LINK_TEST), about `mb` MB."""
    codec = FrameCodec(get_profile("ktcs-type1"))
    rng = random.Random(3)
    samples = [
        codec.encode_message(1, "ALL_INFO", statuses=[rng.randrange(2) for _ in range(132)]),
        codec.encode_message(2, "CHANGE", items=[[rng.randrange(400), 1] for _ in range(5)]),
        codec.encode(3, 0x0006),
        codec.encode(4, 0x0003),
    ]
    block = "".join(
        f"{k * 0.01:.6f} {'ixl>atc' if k % 2 else 'atc>ixl'} {samples[k % 4].hex(' ').upper()}\n"
        for k in range(4000)
    )
    with path.open("w", encoding="utf-8") as f:
        f.write("# ktcs-bench hex log v1: <seconds since start> <direction> <frame bytes in hex>\n")
        for _ in range(max(1, int(mb * 1e6 / len(block)))):
            f.write(block)


def corrupted_capture(path: Path, mb: float) -> None:
    """Type I CHANGE frames that all fail their CRC, one a line, about `mb` MB."""
    rng = random.Random(21)
    with path.open("w", encoding="utf-8") as f:
        written = 0
        while written < mb * 1e6:
            lines = "".join(
                (bytes((2, 3, 0, rng.randrange(256), 2, 0)) + rng.randbytes(8)).hex(" ").upper()
                + "\n"
                for _ in range(1000)
            )
            written += f.write(lines)


def measured(argv: list[str]) -> tuple[float, float, float]:
    """(peak RSS MB, wall s, CPU s) of one subprocess, from a fresh wrapper whose only child
    it is (its RUSAGE_CHILDREN is that subprocess's alone)."""
    probe = (
        "import json, resource, subprocess, sys, time\n"
        "t0 = time.perf_counter()\n"
        "subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, check=False)\n"
        "wall = time.perf_counter() - t0\n"
        "ru = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
        "print(json.dumps([ru.ru_maxrss / 1024, wall, ru.ru_utime + ru.ru_stime]))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True)
    peak, wall, cpu = json.loads(out.stdout)
    return float(peak), float(wall), float(cpu)


def peak_rss_mb(argv: list[str]) -> float:
    return measured(argv)[0]


def bench_memory(mb_large: float, folder: Path) -> None:
    sizes = (mb_large / 4, mb_large)
    for extra in (["--json", "--profile", "ktcs-type1"], ["--profile", "auto"]):
        peaks = []
        for mb in sizes:
            path = folder / f"cap{mb}.hex"
            if not path.exists():
                hexlog_capture(path, mb)
            argv = [sys.executable, "-m", "ktcs_bench.cli.main", "decode", *extra, str(path)]
            peaks.append(peak_rss_mb(argv))
        shown = ", ".join(f"{mb:g} MB: {p:.0f} MB" for mb, p in zip(sizes, peaks, strict=True))
        print(f"decode {' '.join(extra)} peak RSS by capture size: {shown}")


def bench_corrupted(sizes: list[float], folder: Path) -> None:
    """One table: per size, peak RSS, wall and CPU time, CPU s/MB, and the marginal CPU s/MB
    from the size before (start-up left out): flat when the time is linear in the input."""
    print("decode on corrupted input (every frame fails its CRC), by input size:")
    print(f"  {'options':<26} {'MB':>5} {'peak RSS':>9} {'wall s':>7} {'CPU s':>7} "
          f"{'CPU s/MB':>9} {'marginal':>9}")  # fmt: skip
    for extra in (["--json", "--protocol", "type1"], ["--profile", "auto"]):
        before: tuple[float, float] | None = None
        for mb in sizes:
            path = folder / f"corrupted{mb:g}.hex"
            if not path.exists():
                corrupted_capture(path, mb)
            real_mb = path.stat().st_size / 1e6
            argv = [sys.executable, "-m", "ktcs_bench.cli.main", "decode", *extra, str(path)]
            peak, wall, cpu = measured(argv)
            marginal = "" if before is None else f"{(cpu - before[1]) / (real_mb - before[0]):9.2f}"
            before = real_mb, cpu
            print(f"  {' '.join(extra):<26} {real_mb:5.1f} {peak:6.0f} MB {wall:7.2f} {cpu:7.2f} "
                  f"{cpu / real_mb:9.2f} {marginal:>9}")  # fmt: skip
    print(
        "  (marginal: CPU s/MB from the size before; under auto the first 4 MiB decoded are "
        "decoded three times -- two profiles vote, the winner prints -- the rest once)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--frames", type=int, default=100_000, help="CHANGE frames for the ratio")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved runs of each")
    ap.add_argument("--mb", type=float, default=10.0, help="larger capture size for the memory")
    ap.add_argument(
        "--corrupt",
        default="1,3,10,30",
        help="sizes (MB) of the corrupted captures, comma-separated",
    )
    ap.add_argument(
        "--only",
        choices=("ratio", "memory", "corrupted"),
        help="run one part (default: all three)",
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.only in (None, "ratio"):
            floor, ours = bench_json(args.frames, args.rounds, folder)
            ratio = ours / floor
            print(f"decode --json, {args.frames} CHANGE frames: plain script {floor:.2f} s, "
                  f"ktcs-bench {ours:.2f} s -> {ratio:.2f}x  (goal <= 1.5x: "
                  f"{'met' if ratio <= 1.5 else 'NOT met'})")  # fmt: skip
        if args.only in (None, "memory"):
            bench_memory(args.mb, folder)
        if args.only in (None, "corrupted"):
            bench_corrupted([float(mb) for mb in args.corrupt.split(",")], folder)


if __name__ == "__main__":
    main()
