"""`decode` streams: its peak memory does not grow with the input, `--profile auto` included.

Each decode runs as a subprocess under a fresh wrapper whose only child it is, so the wrapper's
RUSAGE_CHILDREN peak RSS is that decode's alone. Two captures, one three times the other, must
peak within a few MB of each other (a decode that holds its input, its records or its output
grows by about 20 bytes of memory per byte of hex log)."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from ktcs_bench.codec import FrameCodec, get_profile

GROWTH_ALLOWED_MB = 10.0


def hex_log(path: Path, blocks: int, one_line: bool = False) -> None:
    """`blocks` times the same 2,000 lines of Type I traffic (about 0.3 MB); `one_line`: the
    same bytes as one line of compact hex, with no end of line anywhere."""
    codec = FrameCodec(get_profile("ktcs-type1"))
    samples = [
        codec.encode_message(1, "ALL_INFO", statuses=[k & 1 for k in range(132)]),
        codec.encode_message(2, "CHANGE", items=[[k, 1] for k in range(5)]),
        codec.encode(3, 0x0006),
        bytes.fromhex("02 FF 03 AA 55"),  # garbage between frames, a false STX in it
    ]
    block = "".join(
        f"{k * 0.01:.6f} ixl>atc {samples[k % 4].hex(' ').upper()}\n" for k in range(2000)
    )
    if one_line:
        block = "".join(samples[k % 4].hex() for k in range(2000)) * 2  # about as many bytes
    with path.open("w", encoding="utf-8") as f:
        for _ in range(blocks):
            f.write(block)


def peak_rss_mb(*args: str) -> float:
    probe = (
        "import resource, subprocess, sys\n"
        "done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)\n"
        "assert done.returncode in (0, 1), done.stderr\n"
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
    )
    argv = [sys.executable, "-c", probe, sys.executable, "-m", "ktcs_bench.cli.main", *args]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return int(out.stdout) / 1024


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path]]:
    folder = tmp_path_factory.mktemp("captures")
    out = {}
    for kind in ("lines", "one-line"):
        small, large = folder / f"small-{kind}.hex", folder / f"large-{kind}.hex"
        hex_log(small, 7, kind == "one-line")  # 2 MB: past the 1 MiB blocks decode reads
        hex_log(large, 21, kind == "one-line")  # and the auto window
        out[kind] = small, large
    return out


@pytest.mark.parametrize(
    ("kind", "options"),
    [
        ("lines", ("--json", "--profile", "ktcs-type1")),
        ("lines", ("--profile", "auto")),
        ("one-line", ("--json", "--profile", "ktcs-type1")),
    ],
    ids=["json", "auto", "one-line"],
)
def test_decode_peak_memory_does_not_grow_with_the_input(
    captures: dict[str, tuple[Path, Path]], kind: str, options: tuple[str, ...]
) -> None:
    small, large = captures[kind]
    assert large.stat().st_size == 3 * small.stat().st_size > 2_000_000
    low = peak_rss_mb("decode", *options, str(small))
    high = peak_rss_mb("decode", *options, str(large))
    assert high - low < GROWTH_ALLOWED_MB, (low, high)


# -- corrupted input (issue 21 item 11) -----------------------------------------------------------
CORRUPTED_OVER_BASELINE_MB = 25.0


def corrupted_capture(path: Path, mb: float, hex_log: bool) -> None:
    """Type I CHANGE frames with bad CRCs, about `mb` MB: `02 03 00 XX 02 00` and 8 random bytes
    a line (no profile's CRC checks, so --profile auto never decides early), bare or as a hex
    log (a record begun on every line)."""
    rng = random.Random(11)
    with path.open("w", encoding="utf-8") as f:
        written, k = 0, 0
        while written < mb * 1e6:
            frame = bytes((2, 3, 0, rng.randrange(256), 2, 0)) + rng.randbytes(8)
            line = frame.hex(" ").upper() + "\n"
            if hex_log:
                line = f"{k * 0.01:.6f} {'ixl>atc' if k % 2 else 'atc>ixl'} {line}"
            written += f.write(line)
            k += 1


@pytest.mark.parametrize(
    ("hex_log", "options"),
    [(False, ("--json", "--protocol", "type1")), (True, ("--profile", "auto"))],
    ids=["json-bare-lines", "auto-hex-log"],
)
def test_decode_of_corrupted_frames_holds_one_slice_of_records_at_a_time(
    tmp_path: Path, hex_log: bool, options: tuple[str, ...]
) -> None:
    """Megabytes of frames that all fail their CRC: --profile auto finds no profile whose CRC
    checks and holds its whole window (the first 4 MiB decoded) before it decides. Decoding and
    printing that window in one go held every record and line of output at once (86 MB for 3 MB
    of input, 212 MB for 10 MB); now it peaks within a few MB of a one-frame decode."""
    capture = tmp_path / "corrupted.hex"
    corrupted_capture(capture, 4.5, hex_log)
    baseline = tmp_path / "one.hex"
    corrupted_capture(baseline, 0.0001, hex_log)
    low = peak_rss_mb("decode", *options, str(baseline))
    high = peak_rss_mb("decode", *options, str(capture))
    assert high - low < CORRUPTED_OVER_BASELINE_MB, (low, high)
