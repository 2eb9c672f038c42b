"""Random, truncated and garbage captures: tshark with the dissector never reports a Lua error (nor
a malformed packet), and still frames every direction exactly as the bench's stream decoder does.

Each hypothesis example is one capture of many packets -- valid frames of every opcode, frames
with flipped bits, cut short, with LEN out of range, false STX bytes in garbage, random bytes --
cut into packets at random places, in both directions, for Type I (LINKTYPE_USER0) and Type II
(TCP, with and without TCP reassembly); then the pcapng file itself cut short."""

from __future__ import annotations

import random
from pathlib import Path

from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from ktcs_bench.capture import CaptureRecord
from ktcs_bench.codec.frame import FrameCodec
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.codec.render import to_json
from ktcs_bench.codec.stream import StreamDecoder

from .harness import (
    Rec,
    as_record,
    assert_agree,
    dissected,
    run_tshark,
    tshark_json,
    write_pcapng,
)

PROFILES = ["ktcs-type1", "ktcs-type1-fig7", "ktcs-type2"]
DIRECTIONS = {"type1": ("ixl>atc", "atc>ixl"), "type2": ("ixl>ctc", "ctc>ixl")}
# an example is a seed and a tshark run: shrinking a seed finds nothing smaller, only slower
NO_SHRINK = (Phase.explicit, Phase.reuse, Phase.generate)


def frame_bytes(rng: random.Random, profile: FrameProfile) -> bytes:
    """A valid frame, or one with something wrong with it."""
    codec = FrameCodec(profile)
    opcodes = list(profile.opcodes.by_op.values())
    opcode = rng.choice(opcodes)
    if rng.random() < 0.1:
        op = rng.randrange(1 << (8 * dict(profile.header)["op"]))  # perhaps unknown
    else:
        op = opcode.op
    size = opcode.fixed_size + opcode.item_size * rng.randint(0, 4)
    if opcode.statuses:
        size = rng.randint(0, 40)
    if rng.random() < 0.1:
        size = rng.randint(0, 12)  # perhaps not the opcode's layout
    seq = rng.randrange(1 << (8 * dict(profile.header)["seq"]))
    sub = rng.choice(list(opcode.subs) or [0]) if profile.has_sub else None
    frame = bytearray(codec.encode(seq, op, rng.randbytes(size), sub))
    damage = rng.random()
    if damage < 0.15:  # bit errors anywhere
        for _ in range(rng.randint(1, 3)):
            frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
    elif damage < 0.22:  # cut short
        frame = frame[: rng.randrange(1, len(frame))]
    elif damage < 0.27:  # LEN far out of range
        off, width = profile.offset_of("len")
        frame[off : off + width] = b"\xff" * width
    return bytes(frame)


def stream_bytes(rng: random.Random, profile: FrameProfile) -> bytes:
    out = bytearray()
    for _ in range(rng.randint(0, 25)):
        kind = rng.random()
        if kind < 0.75:
            out += frame_bytes(rng, profile)
        elif kind < 0.9:  # garbage, perhaps with a false STX announcing a long frame
            junk = bytearray(rng.randbytes(rng.randint(1, 12)))
            if rng.random() < 0.5:
                junk[rng.randrange(len(junk))] = profile.stx
            out += junk
        else:
            out += bytes([profile.stx]) + rng.randbytes(rng.randint(0, 8))
    return bytes(out)


def chunked(rng: random.Random, data: bytes, direction: str, t0: float) -> list[CaptureRecord]:
    """The bytes in packets of random sizes: several frames in one, one frame over several."""
    out, pos, t = [], 0, t0
    while pos < len(data):
        n = rng.choice([1, 2, 3, 7, 11, 20, 64, 200])
        out.append(CaptureRecord(t, direction, data[pos : pos + n]))
        pos += n
        t += 0.001
    return out


def python_records(data: bytes, profile: FrameProfile) -> list[Rec]:
    """What `decode --json` prints, from the same code (in-process: hundreds of captures)."""
    dec = StreamDecoder(profile)
    return [as_record(to_json(r, profile)) for r in dec.feed(data) + dec.close()]


@settings(max_examples=20, derandomize=True, phases=NO_SHRINK)
@given(
    seed=st.integers(0, 2**32 - 1), which=st.sampled_from(PROFILES), tcp_reassembly=st.booleans()
)
def test_random_captures_no_lua_error_and_the_stream_decoders_framing(
    lua: Path, tmp_path_factory: object, seed: int, which: str, tcp_reassembly: bool
) -> None:
    rng = random.Random(seed)
    profile = get_profile(which)
    link = profile.protocol
    tmp = Path(tmp_path_factory.mktemp("fuzz"))  # type: ignore[attr-defined]
    directions = DIRECTIONS[link]
    data = {d: stream_bytes(rng, profile) for d in directions}
    packets = sorted(
        (r for d in directions for r in chunked(rng, data[d], d, 1.0 + rng.random())),
        key=lambda r: r.time or 0.0,
    )
    cap = write_pcapng(tmp / "cap.pcapng", packets, link)
    args = ["-o", f"ktcs{link[-1]}.profile:{which}"]
    if link == "type2":
        args += ["-d", "tcp.port==5020,ktcs2"]
        if not tcp_reassembly:
            args += ["-o", "tcp.desegment_tcp_streams:FALSE"]
    got = dissected(tshark_json(lua, cap, *args), f"ktcs{link[-1]}")
    assert_agree(got, {d: python_records(data[d], profile) for d in directions})
    # the same capture cut short anywhere: tshark complains about the file, never about Lua
    raw = cap.read_bytes()
    cut = tmp / "cut.pcapng"
    cut.write_bytes(raw[: rng.randrange(28, len(raw))])
    done = run_tshark(lua, cut, "-V", *args)
    assert "Lua Error" not in done.stdout + done.stderr, done.stdout[-2000:]
    assert "Malformed Packet: ktcs" not in done.stdout  # an exception in our dissector


@settings(max_examples=10, derandomize=True, phases=NO_SHRINK)
@given(seed=st.integers(0, 2**32 - 1))
def test_pure_noise_packets_and_stray_ip_never_raise(
    lua: Path, tmp_path_factory: object, seed: int
) -> None:
    """Packets of random bytes on USER0 and random TCP payloads (the heuristic looks at them)."""
    rng = random.Random(seed)
    tmp = Path(tmp_path_factory.mktemp("noise"))  # type: ignore[attr-defined]
    t1 = [CaptureRecord(1 + k / 100, rng.choice(DIRECTIONS["type1"]), rng.randbytes(rng.randint(1, 300)))
          for k in range(40)]  # fmt: skip
    t2 = [CaptureRecord(1 + k / 100, rng.choice(DIRECTIONS["type2"]), rng.randbytes(rng.randint(1, 300)))
          for k in range(40)]  # fmt: skip
    for name, records, link in (("t1", t1, "type1"), ("t2", t2, "type2")):
        cap = write_pcapng(tmp / f"{name}.pcapng", records, link)
        done = run_tshark(lua, cap, "-V")
        assert done.returncode == 0, done.stderr
        assert "Lua Error" not in done.stdout + done.stderr, done.stdout[-2000:]
        assert "Malformed Packet: ktcs" not in done.stdout  # an exception in our dissector
