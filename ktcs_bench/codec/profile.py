"""Frame profiles read from `protocols/*.yaml`, checked key by key, with the fast-path layout derived.

A profile says where each header field sits, what LEN counts, what the CRC covers and how wide it
is on the wire. The hot path never looks at the YAML again: it uses the `struct.Struct` for the
header and the offsets computed here once.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from ktcs_bench.codec.crc import CrcFunction, CrcSpec
from ktcs_bench.codec.opcodes import FieldSpec, Opcode, OpcodeTable
from ktcs_bench.datafiles import data_dir, load_mapping
from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.schema import Shape, convert, located

HEADER_FIELDS = ("len", "seq", "op", "sub")
_SIZE_FMT = {1: "B", 2: "H", 4: "I"}
# A LEN wider than this cannot be a serial/TCP frame of ours; it also bounds every buffer.
MAX_LEN_CEILING = 65535


@dataclass(frozen=True)
class FrameProfile:
    """One wire profile. Offsets are from the STX byte; `data` starts at `header_size`."""

    name: str
    protocol: str
    description: str
    source: str
    stx: int
    etx: int | None
    little: bool
    header: tuple[tuple[str, int], ...]
    length_counts: frozenset[str]
    max_len: int
    crc_spec: CrcSpec
    crc_first: str
    crc_last: str
    crc_size: int
    crc_pad: int
    opcodes: OpcodeTable
    nak_reasons: Mapping[int, str]
    # frames without DATA by (seq, op, sub), made by any codec of this profile (`FrameCodec`):
    # every link of a lab sends its ACKs and LINK_TESTs, one per SEQ, the same for all of them.
    # Not an argument: `dataclasses.replace` gives a changed profile a cache of its own
    empty_frames: dict[tuple[int, int, int | None], bytes] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    # -- derived layout (computed once, used by the hot path) --
    @property
    def header_size(self) -> int:
        """STX plus the header fields: where DATA starts."""
        return 1 + sum(size for _, size in self.header)

    @property
    def trailer_size(self) -> int:
        return self.crc_size + self.crc_pad + (0 if self.etx is None else 1)

    def offset_of(self, name: str) -> tuple[int, int]:
        """(offset, size) of a header field; STX is at 0."""
        if name == "stx":
            return 0, 1
        off = 1
        for fname, size in self.header:
            if fname == name:
                return off, size
            off += size
        raise KeyError(name)

    @property
    def has_sub(self) -> bool:
        return any(n == "sub" for n, _ in self.header)

    @property
    def fixed_counted(self) -> int:
        """Header bytes that LEN counts (the rest of LEN is DATA)."""
        return sum(size for n, size in self.header if n in self.length_counts)

    @property
    def max_data(self) -> int:
        return self.max_len - self.fixed_counted

    def frame_size(self, data_len: int) -> int:
        return self.header_size + data_len + self.trailer_size

    def crc_span(self, data_len: int) -> tuple[int, int]:
        """[start, end) of the bytes the CRC covers in a frame with `data_len` bytes of DATA."""
        start = self.offset_of(self.crc_first)[0]
        if self.crc_last == "data":
            return start, self.header_size + data_len
        off, size = self.offset_of(self.crc_last)
        return start, off + size

    def header_struct(self) -> struct.Struct:
        order = "<" if self.little else ">"
        return struct.Struct(order + "".join(_SIZE_FMT[size] for _, size in self.header))

    def crc_function(self) -> CrcFunction:
        return _crc_function(self.crc_spec)

    def nak_reason_name(self, reason: int) -> str:
        return self.nak_reasons.get(reason, f"reason {reason}")

    def nak_reason(self, meaning: str) -> int:
        """The NAK reason number this profile gives `meaning` ("crc error", "frame timeout",
        "length/format error", "unknown opcode"): the one its `nak_reasons` names so, a remark in
        brackets aside ("frame timeout (ΔR)"). ConfigError when it names none."""
        for number, name in self.nak_reasons.items():
            if name.split(" (", 1)[0].strip().lower() == meaning:
                return number
        raise ConfigError(
            self.source, "nak_reasons", f"profile {self.name} needs {meaning!r}, named none"
        )

    def items_per_frame(self, op_name: str) -> int:
        """The most items one frame of `op_name` carries: what DATA holds after its fixed fields,
        in items of its width."""
        opcode = self.opcodes.by_name.get(op_name)
        if opcode is None or not opcode.item_size:
            raise ConfigError(
                self.source, "opcodes", f"profile {self.name}: no {op_name} with items"
            )
        return (self.max_data - opcode.fixed_size) // opcode.item_size


@cache
def _crc_function(spec: CrcSpec) -> CrcFunction:
    return spec.function()


class _Reader:
    """Reads one YAML mapping, turning every problem into a ConfigError with its key path."""

    def __init__(self, file: Path) -> None:
        self.file = file

    def fail(self, place: str, problem: str) -> ConfigError:
        return located(self.file, place, problem)

    def mapping(self, value: Any, place: str, keys: tuple[str, ...] = ()) -> dict[str, Any]:
        """`value` as a mapping; with `keys`, any other key is refused (a misspelt key would
        otherwise be ignored and give a silently different codec)."""
        if not isinstance(value, dict):
            raise self.fail(place, f"must be a mapping, not {type(value).__name__}")
        for k in value:
            if keys and k not in keys:
                where = f"{place}.{k}" if place else str(k)
                raise self.fail(where, f"unknown key (known: {', '.join(keys)})")
        return value

    def get(self, m: Mapping[str, Any], key: str, place: str, kind: type | tuple[type, ...]) -> Any:
        where = f"{place}.{key}" if place else key
        if key not in m:
            raise self.fail(where, "missing key")
        return self.typed(m[key], where, kind)

    def optional(
        self,
        m: Mapping[str, Any],
        key: str,
        place: str,
        kind: type | tuple[type, ...],
        default: Any,
    ) -> Any:
        value = m.get(key)
        return default if value is None else self.typed(value, f"{place}.{key}", kind)

    def typed(self, value: Any, where: str, kind: type | tuple[type, ...]) -> Any:
        kinds = kind if isinstance(kind, tuple) else (kind,)
        # YAML's true/false are ints to Python; a bool is never a number here
        if not isinstance(value, kinds) or (bool not in kinds and isinstance(value, bool)):
            names = " or ".join(_KIND_NAMES.get(k, k.__name__) for k in kinds)
            raise self.fail(where, f"must be {names}, not {excerpt(value)}")
        return value

    def number(self, m: Mapping[str, Any], key: str, place: str, low: int, high: int) -> int:
        value = int(self.get(m, key, place, int))
        if not low <= value <= high:
            raise self.fail(f"{place}.{key}", f"must be {low:#x}..{high:#x}, not {value:#x}")
        return value


_KIND_NAMES = {int: "an integer", str: "a string", bool: "true or false", list: "a list",
               dict: "a mapping"}  # fmt: skip
_CRC_KEYS = ("poly", "reflect", "init", "xor_out", "check")
_OPCODE_KEYS = ("op", "name", "fields", "items", "statuses", "control", "subs", "reasons")
# CRC widths crcmod computes that fit the largest CRC field (4 bytes)
CRC_WIDTHS = (8, 16, 24, 32)
MAX_CRC_PAD = 16
MAX_OPCODE = 0xFFFF
# keys of a parsed payload besides its fields: a field may not take these names
_RESERVED_FIELD_NAMES = ("items", "statuses")


def _crc_spec(r: _Reader, name: str, raw: Any) -> CrcSpec:
    place = f"crc_algorithms.{name}"
    cm = r.mapping(raw, place, _CRC_KEYS)
    poly = r.get(cm, "poly", place, int)
    width = poly.bit_length() - 1
    if width not in CRC_WIDTHS:
        raise r.fail(
            f"{place}.poly",
            f"must be a polynomial written with its top bit, of {', '.join(map(str, CRC_WIDTHS))} "
            f"bits (0x18005 is CRC-16/ARC), not {poly:#x} ({max(width, 0)} bits)",
        )
    top = (1 << width) - 1
    check = cm.get("check")
    spec = CrcSpec(
        str(name),
        poly,
        bool(r.get(cm, "reflect", place, bool)),
        r.number(cm, "init", place, 0, top),
        r.number(cm, "xor_out", place, 0, top),
        None if check is None else r.number(cm, "check", place, 0, top),
    )
    try:
        fn = spec.function()
    except ValueError as exc:  # crcmod's own refusal, should a case slip past the checks above
        raise r.fail(place, str(exc)) from None
    if spec.check is not None and fn(b"123456789") != spec.check:
        raise r.fail(place, f"check value over '123456789' is not {spec.check:#06x}")
    return spec


def _field_specs(r: _Reader, raw: Any, place: str) -> tuple[FieldSpec, ...]:
    if not isinstance(raw, list):
        raise r.fail(place, "must be a list of {name, type}")
    specs = []
    for i, f in enumerate(raw):
        fm = r.mapping(f, f"{place}[{i}]", ("name", "type"))
        name = r.get(fm, "name", f"{place}[{i}]", str)
        typ = r.get(fm, "type", f"{place}[{i}]", str)
        if not name.isidentifier() or name in _RESERVED_FIELD_NAMES:
            raise r.fail(f"{place}[{i}].name", f"{excerpt(name)} cannot name a field")
        if typ not in ("u8", "u16", "u32"):
            raise r.fail(f"{place}[{i}].type", f"must be u8, u16 or u32, not {excerpt(typ)}")
        specs.append(FieldSpec(name, typ))
    return tuple(specs)


def _int_names(r: _Reader, raw: Any, place: str, high: int) -> dict[int, str]:
    if raw is None:
        return {}
    m = r.mapping(raw, place)
    out: dict[int, str] = {}
    for k, v in m.items():
        if not isinstance(k, int) or isinstance(k, bool) or not 0 <= k <= high:
            raise r.fail(f"{place}.{k}", f"keys must be integers 0..{high:#x}")
        out[k] = str(v)
    return out


def _opcode(r: _Reader, raw: Any, place: str, little: bool) -> Opcode:
    m = r.mapping(raw, place, _OPCODE_KEYS)
    op = r.number(m, "op", place, 0, MAX_OPCODE)
    name = r.get(m, "name", place, str).strip()
    if not name or any(c.isspace() or c in "=,:" for c in name):
        raise r.fail(
            f"{place}.name", f"{excerpt(name)} cannot name an opcode (used on command lines)"
        )
    shapes = [k for k in ("items", "statuses") if m.get(k)]
    if len(shapes) > 1:
        raise r.fail(place, "an opcode carries items or statuses, not both")
    fields = _field_specs(r, r.optional(m, "fields", place, list, []), f"{place}.fields")
    items = _field_specs(r, r.optional(m, "items", place, list, []), f"{place}.items")
    for part, specs in (("fields", fields), ("items", items)):
        seen: set[str] = set()
        for i, spec in enumerate(specs):
            if spec.name in seen:
                raise r.fail(f"{place}.{part}[{i}].name", f"{excerpt(spec.name)} appears twice")
            seen.add(spec.name)
    return Opcode(
        op=op,
        name=name.upper(),
        little=little,
        fields=fields,
        items=items,
        statuses=r.optional(m, "statuses", place, bool, False),
        control=r.optional(m, "control", place, bool, False),
        subs=_int_names(r, m.get("subs"), f"{place}.subs", 0xFFFFFFFF),
        reasons=_int_names(r, m.get("reasons"), f"{place}.reasons", 0xFFFFFFFF),
    )


def _opcode_list(r: _Reader, raw: Any, place: str, little: bool) -> list[tuple[str, Opcode]]:
    """The opcodes of one list, each with its place; a number or name twice is refused."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise r.fail(place, f"must be a list of opcodes, not {excerpt(raw)}")
    out: list[tuple[str, Opcode]] = []
    numbers: dict[int, str] = {}
    names: dict[str, str] = {}
    for i, oraw in enumerate(raw):
        where = f"{place}[{i}]"
        o = _opcode(r, oraw, where, little)
        if o.op in numbers:
            raise r.fail(f"{where}.op", f"opcode {o.op:#06x} is also {numbers[o.op]}")
        if o.name in names:
            raise r.fail(f"{where}.name", f"opcode name {o.name} is also {names[o.name]}")
        numbers[o.op], names[o.name] = where, where
        out.append((where, o))
    return out


def _opcode_table(
    r: _Reader, base: list[tuple[str, Opcode]], overrides: list[tuple[str, Opcode]],
    header: dict[str, int],
) -> OpcodeTable:  # fmt: skip
    """The shared opcodes with a profile's overrides (which replace by number), checked against
    the profile's OP and SUB widths."""
    table = {o.op: (where, o) for where, o in base}
    for where, o in overrides:
        table[o.op] = (where, o)
    names: dict[str, str] = {}
    op_max = (1 << (8 * header["op"])) - 1
    sub_max = (1 << (8 * header["sub"])) - 1 if "sub" in header else None
    for where, o in table.values():
        if o.op > op_max:
            raise r.fail(f"{where}.op", f"{o.op:#x} does not fit the {header['op']}-byte op field")
        if o.name in names:
            raise r.fail(f"{where}.name", f"opcode name {o.name} is also {names[o.name]}")
        names[o.name] = where
        if o.subs and sub_max is None:
            raise r.fail(f"{where}.subs", "the profile has no sub field")
        if sub_max is not None and any(k > sub_max for k in o.subs):
            raise r.fail(f"{where}.subs", f"keys must fit the {header['sub']}-byte sub field")
    return OpcodeTable.of(o for _, o in table.values())


class _HeaderFieldShape(Shape):
    name: str
    size: int


class _CrcUseShape(Shape):
    algorithm: str
    covers: list[str]
    size: int
    pad: int | None = None


class _ProfileShape(Shape):
    """One profile under `profiles:` (converted one by one, so a message names it)."""

    stx: int
    header: list[_HeaderFieldShape]
    length_counts: list[str]
    max_len: int
    crc: _CrcUseShape
    description: str | None = None
    etx: int | None = None
    byte_order: str = "little"
    opcode_overrides: object = None  # a list of opcodes: `_opcode_list` reads it


class _ProtocolShape(Shape):
    protocol: str
    crc_algorithms: dict[Any, Any]  # NAME -> {poly, reflect, init, xor_out, check}: `_crc_spec`
    profiles: dict[Any, Any]  # NAME -> _ProfileShape
    opcodes: list[Any]  # `_opcode_list`
    nak_reasons: object = None  # `_int_names`


def load_profiles(path: str | Path) -> dict[str, FrameProfile]:
    """Every profile defined in one protocol YAML file, checked whole: every key known, every
    number in range, no opcode number or name twice. A problem is one ConfigError naming the file
    and the key."""
    file = Path(path)
    r = _Reader(file)
    top = convert(load_mapping(file, "protocol"), _ProtocolShape, file)
    if top.protocol not in ("type1", "type2"):
        raise r.fail("protocol", f"must be type1 or type2, not {excerpt(top.protocol)}")
    crcs = {str(name): _crc_spec(r, str(name), raw) for name, raw in top.crc_algorithms.items()}
    nak_reasons = _int_names(r, top.nak_reasons, "nak_reasons", 0xFF)
    profiles: dict[str, FrameProfile] = {}
    for pname, praw in top.profiles.items():
        place = f"profiles.{pname}"
        pm = convert(praw, _ProfileShape, file, place)
        if pm.byte_order not in ("little", "big"):
            raise r.fail(
                f"{place}.byte_order", f"must be little or big, not {excerpt(pm.byte_order)}"
            )
        little = pm.byte_order == "little"
        header = _header(r, pm, place)
        crc_spec, covers = _crc_use(r, pm.crc, f"{place}.crc", crcs, header)
        if pm.etx is not None and not 0 <= pm.etx <= 255:
            raise r.fail(f"{place}.etx", f"must be a byte value 0..255, not {pm.etx}")
        if not 0 <= pm.stx <= 255:
            raise r.fail(f"{place}.stx", f"must be a byte value 0..255, not {pm.stx}")
        base = _opcode_list(r, top.opcodes, "opcodes", little)
        overrides = _opcode_list(r, pm.opcode_overrides, f"{place}.opcode_overrides", little)
        profiles[str(pname)] = FrameProfile(
            name=str(pname),
            protocol=top.protocol,
            description=pm.description or "",
            source=str(file),
            stx=pm.stx,
            etx=pm.etx,
            little=little,
            header=tuple(header),
            length_counts=frozenset(pm.length_counts),
            max_len=pm.max_len,
            crc_spec=crc_spec,
            crc_first=covers[0],
            crc_last=covers[1],
            crc_size=pm.crc.size,
            crc_pad=pm.crc.pad or 0,
            opcodes=_opcode_table(r, base, overrides, dict(header)),
            nak_reasons=nak_reasons,
        )
    return profiles


def _header(r: _Reader, pm: _ProfileShape, place: str) -> list[tuple[str, int]]:
    """A profile's header fields (name, size), what LEN counts and the longest frame, checked."""
    header: list[tuple[str, int]] = []
    for i, h in enumerate(pm.header):
        hp = f"{place}.header[{i}]"
        if h.name not in HEADER_FIELDS:
            raise r.fail(f"{hp}.name", f"must be one of {', '.join(HEADER_FIELDS)}")
        if h.size not in _SIZE_FMT:
            raise r.fail(f"{hp}.size", f"must be 1, 2 or 4, not {h.size}")
        if any(n == h.name for n, _ in header):
            raise r.fail(f"{hp}.name", f"field {excerpt(h.name)} appears twice")
        header.append((h.name, h.size))
    for needed in ("len", "seq", "op"):
        if all(n != needed for n, _ in header):
            raise r.fail(f"{place}.header", f"needs a {excerpt(needed)} field")
    counts = pm.length_counts
    for i, c in enumerate(counts):
        if c != "data" and all(n != c for n, _ in header if n != "len"):
            parts = ", ".join([n for n, _ in header if n != "len"] + ["data"])
            raise r.fail(f"{place}.length_counts[{i}]", f"must be one of {parts}, not {excerpt(c)}")
        if c in counts[:i]:
            raise r.fail(f"{place}.length_counts[{i}]", f"{excerpt(c)} appears twice")
    if "data" not in counts:
        raise r.fail(f"{place}.length_counts", "LEN must count data")
    max_len = pm.max_len
    if not 1 <= max_len <= MAX_LEN_CEILING:
        raise r.fail(f"{place}.max_len", f"must be 1..{MAX_LEN_CEILING}, not {max_len}")
    len_size = dict(header)["len"]
    if max_len >= 1 << (8 * len_size):
        raise r.fail(f"{place}.max_len", f"does not fit the {len_size}-byte len field")
    fixed = sum(size for n, size in header if n in counts)
    if max_len < fixed:
        raise r.fail(f"{place}.max_len", f"must be at least the {fixed} header bytes LEN counts")
    return header


def _crc_use(
    r: _Reader,
    crc: _CrcUseShape,
    place: str,
    crcs: dict[str, CrcSpec],
    header: list[tuple[str, int]],
) -> tuple[CrcSpec, tuple[str, str]]:
    """A profile's `crc:` -- which algorithm, over which span, how wide on the wire, padded."""
    if crc.algorithm not in crcs:
        raise r.fail(f"{place}.algorithm", f"unknown algorithm {excerpt(crc.algorithm)}")
    covers = crc.covers
    names = ("stx", *(n for n, _ in header), "data")
    if len(covers) != 2 or any(c not in names for c in covers):
        raise r.fail(f"{place}.covers", f"must be [first, last] from {', '.join(names)}")
    if names.index(covers[0]) > names.index(covers[1]) or covers[0] == "data":
        raise r.fail(f"{place}.covers", "first must come before last")
    spec = crcs[crc.algorithm]
    if crc.size not in (1, 2, 4) or spec.width_bits > 8 * crc.size:
        raise r.fail(f"{place}.size", f"cannot carry a {spec.width_bits}-bit CRC")
    pad = crc.pad or 0
    if not 0 <= pad <= MAX_CRC_PAD:
        raise r.fail(f"{place}.pad", f"must be 0..{MAX_CRC_PAD} zero bytes, not {pad}")
    return spec, (covers[0], covers[1])


@cache
def shipped_profiles() -> dict[str, FrameProfile]:
    """Profiles of every `protocols/*.yaml` shipped with the package, by name."""
    out: dict[str, FrameProfile] = {}
    for path in sorted(data_dir("protocols").glob("*.yaml")):
        for name, prof in load_profiles(path).items():
            if name in out:
                raise ConfigError(path, f"profiles.{name}", f"also defined in {out[name].source}")
            out[name] = prof
    return out


DEFAULT_PROFILE = {"type1": "ktcs-type1", "type2": "ktcs-type2"}


def profile_names(protocol: str | None = None) -> list[str]:
    return [n for n, p in shipped_profiles().items() if protocol in (None, p.protocol)]


def get_profile(name: str) -> FrameProfile:
    """A shipped profile by name, or a `FILE.yaml:NAME` / `FILE.yaml` path to a profile of one's own."""
    if name.endswith((".yaml", ".yml")) or ".yaml:" in name or ".yml:" in name:
        path, _, pname = name.partition(":") if ":" in name else (name, "", "")
        profiles = load_profiles(path)
        if not pname:
            if len(profiles) != 1:
                raise UsageError(f"{path} holds several profiles; name one as {path}:NAME")
            return next(iter(profiles.values()))
        if pname not in profiles:
            raise UsageError(f"{path} has no profile {excerpt(pname)} (has {', '.join(profiles)})")
        return profiles[pname]
    profiles = shipped_profiles()
    if name in DEFAULT_PROFILE:
        name = DEFAULT_PROFILE[name]
    if name not in profiles:
        raise UsageError(f"unknown profile {excerpt(name)} (shipped: {', '.join(profiles)})")
    return profiles[name]
