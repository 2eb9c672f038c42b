"""The fault injector on its own: bytes and a virtual `now` in, bytes out (no I/O, no clock)."""

from __future__ import annotations

import random

import pytest

from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.errors import UsageError
from ktcs_bench.tap import (
    BitErrors,
    Cut,
    Delay,
    DropBytes,
    DropFrame,
    DuplicateFrame,
    FaultInjector,
    InsertGarbage,
    ReorderFrames,
    parse_command,
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
            out += inj.poll(now)
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
    out += inj.poll(T + 1)  # idle: whatever was held is released
    assert out == junk + fs[1]


def test_partial_frame_is_released_after_the_hold_timeout() -> None:
    fs = frames(1)
    inj = fresh()
    inj.apply(DropFrame(), T)
    assert run(inj, [fs[0][:5]]) == b""
    deadline = inj.next_deadline()
    assert deadline is not None and deadline > T
    assert inj.poll(deadline) == fs[0][:5]


def test_drop_bytes_and_insert_garbage() -> None:
    inj = fresh()
    inj.apply(DropBytes(3), T)
    assert run(inj, [b"abcdef"]) == b"def"
    inj.apply(InsertGarbage(b"\x02\xff\x00"), T)
    assert inj.poll(T) == b"\x02\xff\x00"
    assert run(inj, [b"gh"]) == b"gh"


def test_delay_keeps_order_and_releases_late() -> None:
    inj = fresh()
    inj.apply(Delay(0.5), T)
    inj.feed(b"one", T)
    assert inj.poll(T + 0.4) == b""
    assert inj.next_deadline() == pytest.approx(T + 0.5)
    inj.apply(Delay(0.0), T + 0.45)
    inj.feed(b"two", T + 0.45)  # must not overtake "one"
    assert inj.poll(T + 0.46) == b""
    assert inj.poll(T + 0.5) == b"onetwo"


def test_discard_drops_what_is_queued_for_a_lost_connection() -> None:
    inj = fresh()
    inj.apply(Delay(0.5), T)
    inj.feed(b"stale", T)
    inj.apply(DuplicateFrame(), T)
    inj.feed(frames(1)[0][:4], T)  # half a frame held by the frame stage
    inj.discard()
    assert inj.poll(T + 1.0) == b"" and inj.next_deadline() is None
    assert inj.stats.bytes_dropped == 5 + 4
    fresh_frame = frames(1, 7)[0]
    inj.feed(fresh_frame, T + 1.0)  # the faults themselves still apply to the next connection
    assert inj.poll(T + 1.2) == b"" and inj.poll(T + 1.5) == fresh_frame * 2


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
        assert inj.poll(T + 1.0) == b"fresh", lose


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
    assert inj.poll(T) == fs[0]
    assert run(inj, [fs[1]]) == fs[1]


def test_control_commands_parse_to_faults() -> None:
    names = ("ixl", "atc")
    assert parse_command("ber 1e-3", names).fault == BitErrors(1e-3)
    assert parse_command("drop-frame ixl->atc", names).fault == DropFrame(1, direction="ixl>atc")
    assert parse_command("duplicate 2 atc>ixl", names).fault == DuplicateFrame(
        2, direction="atc>ixl"
    )
    cmd = parse_command("garbage ixl->atc 02 ff 00", names)
    assert cmd.fault == InsertGarbage(b"\x02\xff\x00", direction="ixl>atc")
    assert parse_command("cut", names).fault == Cut()
    assert parse_command("send atc>ixl 0203", names).data == b"\x02\x03"
    assert parse_command("subscribe history", names).history
    for bad in ["", "explode", "ber", "ber x", "ber 2", "drop-frame a->b", "send 02", "cut 3",
                "drop-frame 0", "garbage ixl->atc zz"]:  # fmt: skip
        with pytest.raises(UsageError):
            parse_command(bad, names)
