"""Decoded records (frames, error frames, garbage) and the encoder, for one profile.

A `Frame` keeps its raw bytes and where DATA sits in them; fields are plain ints. A frame whose
checks failed is still a `Frame`, with `error` set ("crc", "etx", "length", "truncated"), so a
receiver can NAK it and a monitor can show it; `Garbage` is a span of bytes that belongs to no frame.
"""

from __future__ import annotations

import operator
import struct
from typing import Any, NamedTuple

from ktcs_bench.codec.opcodes import Opcode
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError


class Frame(NamedTuple):
    """A tuple, so the decoder's hot path builds it in C (`tuple.__new__`) -- about a third of the
    per-frame cost of a dataclass on bulk decodes."""

    offset: int
    raw: bytes
    seq: int | None
    op: int | None
    sub: int | None
    data_start: int
    data_end: int
    crc_packet: int | None
    crc_calc: int | None
    error: str | None = None

    @property
    def data(self) -> bytes:
        return self.raw[self.data_start : self.data_end]

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def crc_ok(self) -> bool:
        return self.crc_packet is not None and self.crc_packet == self.crc_calc


class Garbage(NamedTuple):
    offset: int
    raw: bytes


Record = Frame | Garbage

EMPTY_FRAMES = 4096
"""Frames without DATA a codec keeps made (a link's ACKs and LINK_TESTs: one per SEQ)."""


class FrameCodec:
    """Encoder and whole-frame helpers for one profile (the streaming decoder is `StreamDecoder`)."""

    def __init__(self, profile: FrameProfile) -> None:
        self.profile = p = profile
        order = "<" if p.little else ">"
        sizes = {1: "B", 2: "H", 4: "I"}
        # STX and the header in one struct; arguments picked from (len, seq, op, sub) by position
        self._head = struct.Struct(order + "B" + "".join(sizes[size] for _, size in p.header))
        self._pick = operator.itemgetter(*("len seq op sub".split().index(n) for n, _ in p.header))
        tail_fmt = order + sizes[p.crc_size] + (f"{p.crc_pad}s" if p.crc_pad else "")
        tail_fmt += "" if p.etx is None else "B"
        self._tail = struct.Struct(tail_fmt)
        self._tail_extra = ((bytes(p.crc_pad),) if p.crc_pad else ()) + (
            () if p.etx is None else (p.etx,)
        )
        self._kernel = p.crc_spec.kernel()
        self._fixed = p.fixed_counted
        self._max_data = p.max_data
        self._crc_from = p.offset_of(p.crc_first)[0]
        self._crc_to_header = None if p.crc_last == "data" else sum(p.offset_of(p.crc_last))
        self.seq_modulo = 1 << (8 * dict(p.header)["seq"])
        # frames without DATA (ACK, LINK_TEST, ...) by (seq, op, sub): a link sends the same
        # few again and again, and so do the other links of its profile (bounded: `EMPTY_FRAMES`)
        self._empty = p.empty_frames

    def encode(self, seq: int, op: int, data: bytes = b"", sub: int | None = None) -> bytes:
        """One complete frame. Raises UsageError for values that do not fit the profile."""
        if not data:
            frame = self._empty.get((seq, op, sub))
            if frame is None:
                frame = self._encode(seq, op, data, sub)
                if len(self._empty) < EMPTY_FRAMES:
                    self._empty[(seq, op, sub)] = frame
            return frame
        return self._encode(seq, op, data, sub)

    def _encode(self, seq: int, op: int, data: bytes, sub: int | None) -> bytes:
        if len(data) > self._max_data:
            raise UsageError(
                f"{len(data)} DATA bytes exceed the profile's maximum {self._max_data}"
            )
        try:
            body = self._head.pack(
                self.profile.stx, *self._pick((self._fixed + len(data), seq, op, sub or 0))
            )
        except struct.error as exc:
            raise UsageError(f"a header value does not fit its field: {exc}") from None
        body += data
        fn, init, table, xor = self._kernel
        end = len(body) if self._crc_to_header is None else self._crc_to_header
        crc = xor ^ fn(body[self._crc_from : end] if self._crc_from or end != len(body) else body,
                       init, table)  # fmt: skip
        return body + self._tail.pack(crc, *self._tail_extra)

    def opcode(self, op: int) -> Opcode | None:
        return self.profile.opcodes.get(op)

    def encode_message(
        self, seq: int, op_name: str, sub: int | None = None, **values: Any
    ) -> bytes:
        """Encode by opcode name with payload values: encode_message(1, "CHANGE", items=[[3, 1]])."""
        opcode = self.profile.opcodes.by_name.get(op_name.upper())
        if opcode is None:
            raise UsageError(f"profile {self.profile.name} has no opcode {op_name!r}")
        return self.encode(seq, opcode.op, opcode.build(values), sub)
