"""Decoded records (frames, error frames, garbage) and the encoder, for one profile.

A `Frame` keeps its raw bytes and where DATA sits in them; fields are plain ints. A frame whose
checks failed is still a `Frame`, with `error` set ("crc", "etx", "length", "truncated"), so a
receiver can NAK it and a monitor can show it; `Garbage` is a span of bytes that belongs to no frame.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from ktcs_bench.codec.opcodes import Opcode
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError


@dataclass(slots=True)
class Frame:
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


@dataclass(slots=True)
class Garbage:
    offset: int
    raw: bytes


Record = Frame | Garbage


class FrameCodec:
    """Encoder and whole-frame helpers for one profile (the streaming decoder is `StreamDecoder`)."""

    def __init__(self, profile: FrameProfile) -> None:
        self.profile = profile
        p = profile
        self._crc = p.crc_function()
        self._names = [n for n, _ in p.header]
        self._header = p.header_struct()
        order = "<" if p.little else ">"
        self._crc_struct = struct.Struct(order + {1: "B", 2: "H", 4: "I"}[p.crc_size])
        self._pad = bytes(p.crc_pad)
        self._etx = b"" if p.etx is None else bytes([p.etx])
        self._stx = bytes([p.stx])
        self._fixed = p.fixed_counted
        first, _ = p.offset_of(p.crc_first)
        self._crc_from = first
        self._crc_to_header = None if p.crc_last == "data" else sum(p.offset_of(p.crc_last))
        seq_bits = 8 * dict(p.header)["seq"]
        self.seq_modulo = 1 << seq_bits

    def encode(self, seq: int, op: int, data: bytes = b"", sub: int | None = None) -> bytes:
        """One complete frame. Raises UsageError for values that do not fit the profile."""
        p = self.profile
        length = self._fixed + len(data)
        if len(data) > p.max_data:
            raise UsageError(f"{len(data)} DATA bytes exceed the profile's maximum {p.max_data}")
        values = {"len": length, "seq": seq, "op": op, "sub": 0 if sub is None else sub}
        try:
            head = self._stx + self._header.pack(*(values[n] for n in self._names))
        except struct.error as exc:
            raise UsageError(f"a header value does not fit its field: {exc}") from None
        body = head + data
        end = len(body) if self._crc_to_header is None else self._crc_to_header
        crc = self._crc(body[self._crc_from : end])
        return body + self._crc_struct.pack(crc) + self._pad + self._etx

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
