"""Hypothesis strategies for frames of any shipped profile, built from the opcode layouts."""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

from ktcs_bench.codec.opcodes import Opcode
from ktcs_bench.codec.profile import FrameProfile

_MAX = {"u8": 0xFF, "u16": 0xFFFF, "u32": 0xFFFFFFFF}


@st.composite
def payload_values(draw: st.DrawFn, opcode: Opcode, profile: FrameProfile) -> dict[str, Any]:
    room = profile.max_data - opcode.fixed_size
    values: dict[str, Any] = {f.name: draw(st.integers(0, _MAX[f.type])) for f in opcode.fields}
    if opcode.items:
        item = st.tuples(*(st.integers(0, _MAX[f.type]) for f in opcode.items)).map(list)
        values["items"] = draw(st.lists(item, max_size=min(40, room // opcode.item_size)))
    elif opcode.statuses:
        values["statuses"] = draw(st.lists(st.integers(0, 255), max_size=min(300, room)))
    return values


@st.composite
def messages(
    draw: st.DrawFn, profile: FrameProfile
) -> tuple[int, Opcode, int | None, dict[str, Any]]:
    opcode = draw(st.sampled_from(sorted(profile.opcodes.by_op.values(), key=lambda o: o.op)))
    seq = draw(st.integers(0, 255))
    sub = draw(st.integers(0, 255)) if profile.has_sub else None
    return seq, opcode, sub, draw(payload_values(opcode, profile))


@st.composite
def frames(draw: st.DrawFn, profile: FrameProfile) -> bytes:
    from ktcs_bench.codec.frame import FrameCodec

    seq, opcode, sub, values = draw(messages(profile))
    return FrameCodec(profile).encode(seq, opcode.op, opcode.build(values), sub)
