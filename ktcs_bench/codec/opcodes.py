"""Opcode tables: names, sub-opcode names and payload layouts, with construct codecs built from YAML.

A payload is one of three shapes (or empty): fixed `fields`; repeated `items` (code, state) records;
`statuses`, one byte per code in chart order. construct parses and builds them for display and the
CLI; `items_of()` and `json_items()` are the fast paths (struct.iter_unpack derived from the same
layout) for bulk work. construct is imported when a fixed-field payload is first built or parsed.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ktcs_bench.errors import PeerError, UsageError

_TYPES: dict[str, tuple[str, int]] = {"u8": ("B", 1), "u16": ("H", 2), "u32": ("I", 4)}


class PayloadError(PeerError):
    """DATA does not fit the opcode's layout (NAK reason: length/format)."""


@dataclass(frozen=True, slots=True)
class FieldSpec:
    name: str
    type: str

    @property
    def size(self) -> int:
        return _TYPES[self.type][1]


def _construct_field(spec: FieldSpec, little: bool) -> Any:
    import construct as cs

    return {
        ("u8", True): cs.Int8ul,
        ("u8", False): cs.Int8ub,
        ("u16", True): cs.Int16ul,
        ("u16", False): cs.Int16ub,
        ("u32", True): cs.Int32ul,
        ("u32", False): cs.Int32ub,
    }[(spec.type, little)]


@dataclass(frozen=True)
class Opcode:
    """One opcode: its number, name, sub-opcode names and payload layout."""

    op: int
    name: str
    little: bool = True
    fields: tuple[FieldSpec, ...] = ()
    items: tuple[FieldSpec, ...] = ()
    statuses: bool = False
    control: bool = False
    subs: Mapping[int, str] = field(default_factory=dict)
    reasons: Mapping[int, str] = field(default_factory=dict)
    _item_struct: struct.Struct | None = field(init=False, repr=False, compare=False)
    _fixed: int = field(init=False, repr=False, compare=False)
    _keys: frozenset[str] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        order = "<" if self.little else ">"
        item_struct = None
        if self.items:
            item_struct = struct.Struct(order + "".join(_TYPES[f.type][0] for f in self.items))
        object.__setattr__(self, "_item_struct", item_struct)
        object.__setattr__(self, "_fixed", sum(f.size for f in self.fields))
        shape = ("items",) if self.items else ("statuses",) if self.statuses else ()
        object.__setattr__(self, "_keys", frozenset([f.name for f in self.fields] + list(shape)))

    @property
    def _fields_cs(self) -> Any:
        """The construct Struct of the fixed fields, built on first use."""
        built = self.__dict__.get("_fields_cs_built")
        if built is None:
            import construct as cs

            built = cs.Struct(*(f.name / _construct_field(f, self.little) for f in self.fields))
            object.__setattr__(self, "_fields_cs_built", built)
        return built

    @property
    def fixed_size(self) -> int:
        return self._fixed

    @property
    def item_size(self) -> int:
        return self._item_struct.size if self._item_struct else 0

    def parse(self, data: bytes) -> dict[str, Any]:
        """Decode DATA: {field: value, ..., "items": [[..], ..], "statuses": [..]}."""
        fixed = self._fixed
        if len(data) < fixed:
            raise PayloadError(f"{self.name}: DATA has {len(data)} bytes, needs {fixed}")
        out: dict[str, Any] = {}
        if self.fields:
            parsed = self._fields_cs.parse(data[:fixed])
            out.update({f.name: int(parsed[f.name]) for f in self.fields})
        rest = data[fixed:]
        if self.items:
            out["items"] = self.items_of(rest)
        elif self.statuses:
            out["statuses"] = list(rest)
        elif rest:
            raise PayloadError(f"{self.name}: {len(rest)} unexpected bytes after the payload")
        return out

    def items_of(self, data: bytes) -> list[list[int]]:
        """Fast path: the repeated records of DATA (after any fixed fields are removed)."""
        st = self._item_struct
        if st is None:
            return []
        if len(data) % st.size:
            raise PayloadError(
                f"{self.name}: {len(data)} item bytes is not a multiple of {st.size}"
            )
        return [list(t) for t in st.iter_unpack(data)]

    def json_items(self, data: bytes) -> list[list[int]] | None:
        """The `items` of a frame's JSON record (SPEC §7): its items, or its statuses as
        [code, status] from code 1, or None for a payload of fixed fields only. Raises
        PayloadError exactly where `parse` does; reads no fixed field (the bulk fast path)."""
        fixed = self._fixed
        size = len(data)
        if size < fixed:
            raise PayloadError(f"{self.name}: DATA has {size} bytes, needs {fixed}")
        st = self._item_struct
        if st is not None:
            if (size - fixed) % st.size:
                raise PayloadError(
                    f"{self.name}: {size - fixed} item bytes is not a multiple of {st.size}"
                )
            return [list(t) for t in st.iter_unpack(data[fixed:] if fixed else data)]
        if self.statuses:
            return [[k, s] for k, s in enumerate(data[fixed:], 1)]
        if size > fixed:
            raise PayloadError(f"{self.name}: {size - fixed} unexpected bytes after the payload")
        return None

    def build(self, values: Mapping[str, Any]) -> bytes:
        """Encode DATA from {field: value, "items": [[..]..]} or {"statuses": [..]}. A value the
        opcode does not carry is refused, never dropped."""
        extra = [k for k in values if k not in self._keys]
        if extra:
            carried = ", ".join(sorted(self._keys)) or "nothing (no DATA)"
            raise UsageError(f"{self.name} carries no {', '.join(extra)} (it carries {carried})")
        out = self._build_fields(values) if self.fields else b""
        if self.items:
            out += self.pack_items(values.get("items", ()))
        elif self.statuses:
            statuses = values.get("statuses", ())
            if any(not 0 <= int(s) <= 255 for s in statuses):
                raise UsageError(f"{self.name}: a status must be a byte (0..255)")
            out += bytes(int(s) for s in statuses)
        return out

    def _build_fields(self, values: Mapping[str, Any]) -> bytes:
        import construct as cs

        try:
            return bytes(self._fields_cs.build({f.name: values[f.name] for f in self.fields}))
        except KeyError as exc:
            raise UsageError(f"{self.name}: missing field {exc.args[0]!r}") from None
        except cs.ConstructError as exc:  # a value that does not fit its field
            raise UsageError(f"{self.name}: {exc}") from None

    def pack_items(self, items: Iterable[Iterable[int]]) -> bytes:
        st = self._item_struct
        if st is None:
            raise UsageError(f"{self.name} carries no items")
        try:
            return b"".join(st.pack(*item) for item in items)
        except struct.error as exc:
            raise UsageError(f"{self.name}: bad item ({exc})") from None

    def sub_name(self, sub: int) -> str | None:
        return self.subs.get(sub)


@dataclass(frozen=True)
class OpcodeTable:
    by_op: Mapping[int, Opcode]
    by_name: Mapping[str, Opcode]

    @classmethod
    def of(cls, opcodes: Iterable[Opcode]) -> OpcodeTable:
        ops = list(opcodes)
        return cls({o.op: o for o in ops}, {o.name: o for o in ops})

    def get(self, op: int) -> Opcode | None:
        return self.by_op.get(op)

    def lookup(self, name_or_number: str) -> Opcode | int:
        """An opcode by name (any case) or number ("0x0002", "2"); an unknown number stays an int."""
        key = name_or_number.strip()
        found = self.by_name.get(key.upper())
        if found is not None:
            return found
        try:
            number = int(key, 0)
        except ValueError:
            names = ", ".join(self.by_name)
            raise UsageError(f"unknown opcode {key!r} (known: {names})") from None
        return self.by_op.get(number, number)
