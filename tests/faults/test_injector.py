"""The fault injector on its own: bytes and a virtual `now` in, bytes out (no I/O, no clock)."""

from __future__ import annotations

import itertools
import json
import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.errors import UsageError
from ktcs_bench.faults import (
    BitErrors,
    ByteLoss,
    CorruptFrame,
    Cut,
    Delay,
    DropBytes,
    DropFrame,
    DuplicateFrame,
    Fault,
    FaultInjector,
    InsertGarbage,
    Noise,
    ReorderFrames,
    TruncateFrame,
    fault_from_json,
)

PROFILE = get_profile("ktcs-type1")
CODEC = FrameCodec(PROFILE)
T = 1000.0


def frames(n: int, start: int = 0) -> list[bytes]:
    # DATA holds STX/ETX values on purpose: framing is by LEN
    return [CODEC.encode(start + k, 2, bytes([2, 3, k, 0, 1])) for k in range(n)]


def run(
    inj: FaultInjector, chunks: list[bytes], now: float = T, byte_by_byte: bool = False
) -> bytes:
    out = bytearray()
    for c in chunks:
        pieces = [c[i : i + 1] for i in range(len(c))] if byte_by_byte else [c]
        for p in pieces:
            inj.feed(p, now)
            out += inj.handle_timer(now)
    return bytes(out)


def fresh(seed: int = 1) -> FaultInjector:
    return FaultInjector(PROFILE, random.Random(seed))


def test_transparent_without_faults() -> None:
    data = bytes(range(256)) * 10
    assert run(fresh(), [data]) == data


@pytest.mark.parametrize("rate", [1e-3, 1e-2])
def test_bit_errors_at_about_the_rate(rate: float) -> None:
    inj = fresh()
    inj.apply(BitErrors(rate), T)
    data = bytes(200_000)
    out = run(inj, [data[i : i + 1000] for i in range(0, len(data), 1000)])
    flipped = sum(bin(b).count("1") for b in out)
    expected = rate * 8 * len(data)
    assert flipped == inj.stats.bits_flipped
    assert 0.9 * expected < flipped < 1.1 * expected


def test_bit_errors_replay_with_the_seed() -> None:
    outs = []
    for _ in range(2):
        inj = fresh(seed=42)
        inj.apply(BitErrors(1e-2), T)
        outs.append(run(inj, [bytes(5000)]))
    assert outs[0] == outs[1] and outs[0] != bytes(5000)


@pytest.mark.parametrize("byte_by_byte", [False, True])
def test_drop_frame_removes_exactly_one(byte_by_byte: bool) -> None:
    fs = frames(5)
    inj = fresh()
    inj.apply(DropFrame(), T)
    out = run(inj, fs, byte_by_byte=byte_by_byte)
    assert out == b"".join(fs[1:])
    assert inj.stats.frames_dropped == 1


def test_drop_two_frames_then_transparent() -> None:
    fs = frames(5)
    inj = fresh()
    inj.apply(DropFrame(2), T)
    assert run(inj, fs) == b"".join(fs[2:])


def test_frame_fault_armed_mid_frame_hits_the_next_whole_frame() -> None:
    fs = frames(3)
    inj = fresh()
    out = run(inj, [fs[0][:4]])
    inj.apply(DropFrame(), T)
    out += run(inj, [fs[0][4:], fs[1], fs[2]])
    assert out == fs[0] + fs[2]


def test_duplicate_and_reorder() -> None:
    fs = frames(4)
    inj = fresh()
    inj.apply(DuplicateFrame(), T)
    assert run(inj, fs) == fs[0] + fs[0] + b"".join(fs[1:])
    inj = fresh()
    inj.apply(ReorderFrames(), T)
    assert run(inj, fs, byte_by_byte=True) == fs[1] + fs[0] + fs[2] + fs[3]
    assert inj.stats.frames_reordered == 1


def test_garbage_between_frames_passes_while_framing() -> None:
    fs = frames(3)
    inj = fresh()
    inj.apply(DropFrame(direction=None), T)
    junk = b"\xff\x00\x02\x09"
    out = run(inj, [junk, fs[0], fs[1]])
    out += inj.handle_timer(T + 1)  # idle: whatever was held is released
    assert out == junk + fs[1]


def test_partial_frame_is_released_after_the_hold_timeout() -> None:
    fs = frames(1)
    inj = fresh()
    inj.apply(DropFrame(), T)
    assert run(inj, [fs[0][:5]]) == b""
    deadline = inj.next_deadline()
    assert deadline is not None and deadline > T
    assert inj.handle_timer(deadline) == fs[0][:5]


def test_drop_bytes_and_insert_garbage() -> None:
    inj = fresh()
    inj.apply(DropBytes(3), T)
    assert run(inj, [b"abcdef"]) == b"def"
    inj.apply(InsertGarbage(b"\x02\xff\x00"), T)
    assert inj.handle_timer(T) == b"\x02\xff\x00"
    assert run(inj, [b"gh"]) == b"gh"


def test_delay_keeps_order_and_releases_late() -> None:
    inj = fresh()
    inj.apply(Delay(0.5), T)
    inj.feed(b"one", T)
    assert inj.handle_timer(T + 0.4) == b""
    assert inj.next_deadline() == pytest.approx(T + 0.5)
    inj.apply(Delay(0.0), T + 0.45)
    inj.feed(b"two", T + 0.45)  # must not overtake "one"
    assert inj.handle_timer(T + 0.46) == b""
    assert inj.handle_timer(T + 0.5) == b"onetwo"


def test_discard_drops_what_is_queued_for_a_lost_connection() -> None:
    inj = fresh()
    inj.apply(Delay(0.5), T)
    inj.feed(b"stale", T)
    inj.apply(DuplicateFrame(), T)
    inj.feed(frames(1)[0][:4], T)  # half a frame held by the frame stage
    inj.discard()
    assert inj.handle_timer(T + 1.0) == b"" and inj.next_deadline() is None
    assert inj.stats.bytes_dropped == 5 + 4
    fresh_frame = frames(1, 7)[0]
    inj.feed(fresh_frame, T + 1.0)  # the faults themselves still apply to the next connection
    assert inj.handle_timer(T + 1.2) == b"" and inj.handle_timer(T + 1.5) == fresh_frame * 2


def test_what_was_thrown_away_holds_nothing_back() -> None:
    """Bytes after a discard or a cut are not kept behind the due time of bytes that are gone."""
    for lose in ("discard", "cut"):
        inj = fresh()
        inj.apply(Delay(30.0), T)
        inj.feed(b"stale", T)
        if lose == "discard":
            inj.discard()
        else:
            inj.apply(Cut(), T)
            inj.restore()
        inj.clear(T + 1.0)
        inj.feed(b"fresh", T + 1.0)
        assert inj.handle_timer(T + 1.0) == b"fresh", lose


def test_cut_and_restore() -> None:
    inj = fresh()
    inj.apply(Cut(), T)
    assert run(inj, [b"lost"]) == b""
    inj.restore()
    assert run(inj, [b"kept"]) == b"kept"
    assert inj.stats.bytes_dropped == 4


def test_clear_releases_held_frames() -> None:
    fs = frames(2)
    inj = fresh()
    inj.apply(ReorderFrames(), T)
    assert run(inj, [fs[0]]) == b""
    inj.clear(T)
    assert inj.handle_timer(T) == fs[0]
    assert run(inj, [fs[1]]) == fs[1]


@pytest.mark.parametrize("rate", [1e-3, 1e-2])
def test_byte_loss_at_about_the_rate(rate: float) -> None:
    inj = fresh()
    inj.apply(ByteLoss(rate), T)
    data = bytes(range(256)) * 800
    out = run(inj, [data[i : i + 700] for i in range(0, len(data), 700)])
    lost = len(data) - len(out)
    assert lost == inj.stats.bytes_dropped
    assert 0.9 * rate * len(data) < lost < 1.1 * rate * len(data)


def test_noise_inserts_bursts_with_false_stx_at_about_the_rate() -> None:
    rate = 2e-3
    inj = fresh()
    inj.apply(Noise(rate), T)
    data = bytes([0x55]) * 200_000  # no STX in the data: every 0x02 that comes out is noise
    out = run(inj, [data[i : i + 1000] for i in range(0, len(data), 1000)])
    assert len(out) - len(data) == inj.stats.garbage_inserted
    assert out.replace(b"\x55", b"") != b"" and out.count(b"\x55") >= len(data)
    bursts = rate * len(data)
    assert 0.8 * bursts * 6.5 < inj.stats.garbage_inserted < 1.2 * bursts * 6.5  # 1..12 bytes
    assert 0.3 * bursts < out.count(PROFILE.stx.to_bytes(1, "little")) < 0.8 * bursts


@given(cuts=st.lists(st.integers(0, 3000), max_size=30), seed=st.integers(0, 2**32))
def test_random_faults_do_not_depend_on_how_the_stream_is_chunked(
    cuts: list[int], seed: int
) -> None:
    data = bytes(range(256)) * 12
    outs = []
    for chunking in ([0, len(data)], sorted({0, len(data), *cuts})):
        inj = fresh(seed)
        for fault in (BitErrors(5e-3), ByteLoss(5e-3), Noise(5e-3)):
            inj.apply(fault, T)
        chunks = [data[i:j] for i, j in itertools.pairwise(chunking)]
        outs.append(run(inj, chunks))
    assert outs[0] == outs[1] and outs[0] != data


def test_corrupt_frame_xors_one_byte_of_the_next_frame_only() -> None:
    fs = frames(3)
    inj = fresh()
    inj.apply(CorruptFrame(-5, 0x10), T)
    out = run(inj, fs, byte_by_byte=True)
    bad = bytearray(fs[0])
    bad[-5] ^= 0x10
    assert out == bytes(bad) + fs[1] + fs[2]
    assert inj.stats.frames_corrupted == 1


def test_truncate_frame_cuts_the_tail_of_the_next_frame_only() -> None:
    fs = frames(3)
    inj = fresh()
    inj.apply(TruncateFrame(4), T)
    assert run(inj, fs) == fs[0][:-4] + fs[1] + fs[2]
    assert inj.stats.frames_truncated == 1 and inj.stats.bytes_dropped == 4


ALL_FAULTS = [BitErrors(1e-3), ByteLoss(0.5, direction="a>b"), Noise(1e-4, 3), DropFrame(2),
              DropBytes(7), InsertGarbage(b"\x02\xff"), DuplicateFrame(direction="b>a"),
              ReorderFrames(), CorruptFrame(-5, 0x10), TruncateFrame(3), Delay(1.5), Cut()]  # fmt: skip


@pytest.mark.parametrize("fault", ALL_FAULTS, ids=lambda f: f.verb)
def test_every_fault_survives_its_json_form(fault: Fault) -> None:
    as_json = fault.to_json()
    assert (
        as_json["cmd"] == fault.verb and fault_from_json(json.loads(json.dumps(as_json))) == fault
    )


@pytest.mark.parametrize(
    "bad",
    [{}, {"cmd": "explode"}, {"cmd": "ber"}, {"cmd": "ber", "rate": "0.1"}, {"cmd": "ber", "rate": 2},
     {"cmd": "ber", "rate": True}, {"cmd": "ber", "rate": float("nan")},
     {"cmd": "drop-frame", "count": 0}, {"cmd": "drop-frame", "count": 1.5},
     {"cmd": "garbage", "hex": "zz"}, {"cmd": "garbage", "hex": ""}, {"cmd": "garbage", "hex": 2},
     {"cmd": "corrupt", "at": 3, "mask": 256}, {"cmd": "cut", "direction": 5},
     {"cmd": "delay", "seconds": -1}, {"cmd": "truncate", "tail": 0}],
)  # fmt: skip
def test_bad_json_faults_are_usage_errors(bad: dict[str, object]) -> None:
    with pytest.raises(UsageError):
        fault_from_json(bad)
