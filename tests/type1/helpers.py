"""Shared helpers for the Type I link tests: a pair of links on a virtual bench, wire decoding."""

from __future__ import annotations

from collections.abc import Callable

from ktcs_bench.codec import Frame, FrameCodec, StreamDecoder, get_profile
from ktcs_bench.faults import FaultInjector
from ktcs_bench.transport.virtual import VirtualBench, VirtualWire
from ktcs_bench.type1 import LinkConfig, Type1Link

PROFILE = get_profile("ktcs-type1")
CODEC = FrameCodec(PROFILE)
OPS = {name: op.op for name, op in PROFILE.opcodes.by_name.items()}
# the links in these tests carry short frames: ΔR ≈ 137 ms, ACK timeout ≈ 199 ms at 9600 bit/s
CONFIG = LinkConfig(longest_frame_data=64)


def make_pair(
    state_a: dict[int, int] | None = None,
    state_b: dict[int, int] | None = None,
    config: LinkConfig = CONFIG,
    **bench_args: FaultInjector | int | float | None,
) -> tuple[Type1Link, Type1Link, VirtualBench]:
    a = Type1Link(PROFILE, config, "a", state_provider=provider(state_a or {}))
    b = Type1Link(PROFILE, config, "b", state_provider=provider(state_b or {}))
    return a, b, VirtualBench(a, b, **bench_args)  # type: ignore[arg-type]


def provider(state: dict[int, int]) -> Callable[[int, int], bytes]:
    """ALL_INFO from a {sequence: status} dict (Sequence k is byte k-1)."""

    def statuses(start: int, count: int) -> bytes:
        n = max(state, default=0)
        return bytes(state.get(k, 0) for k in range(start + 1, min(n, start + count) + 1))

    return statuses


def frames_on(wire: VirtualWire, arrived: bool = False) -> list[Frame]:
    """Every frame record on a wire, as sent (default) or as it arrived."""
    dec = StreamDecoder(PROFILE)
    chunks = wire.arrived if arrived else wire.sent
    out = [r for _, d in chunks for r in dec.feed(d) if isinstance(r, Frame)]
    return out + [r for r in dec.close() if isinstance(r, Frame)]


def data_frames(wire: VirtualWire, op: str) -> list[Frame]:
    return [f for f in frames_on(wire) if f.ok and f.op == OPS[op]]
