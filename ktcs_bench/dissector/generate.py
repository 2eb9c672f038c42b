"""The Lua dissector: the wire profiles as a Lua data table, in front of a fixed Lua engine.

The engine (`ktcs.lua`, package data) is readable Lua that knows nothing of any particular
profile: it reads the `KTCS` table written here from the same `FrameProfile` objects the Python
codecs are built from -- header layout, what LEN counts, the CRC's span, width, padding and its
256-entry table, STX/ETX, maximum LEN, the opcode tables with payload layouts, sub-opcode and
reason names -- plus optional code names from a chart. Pure: profiles in, Lua text out.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import NotRequired, TypedDict

from ktcs_bench import __version__
from ktcs_bench.codec.crc import CrcSpec
from ktcs_bench.codec.opcodes import FieldSpec, Opcode
from ktcs_bench.codec.profile import DEFAULT_PROFILE, FrameProfile
from ktcs_bench.codec.stream import GARBAGE_HOLD
from ktcs_bench.errors import UsageError
from ktcs_bench.station_codes.chart import CodeChart

DATA_MARK = "-- @KTCS_DATA@"
PLUGIN_NAME = "ktcs.lua"
_CRC_WIDTHS = (8, 16, 24, 32)


def crc_table(spec: CrcSpec) -> list[int]:
    """The 256-entry table of a CRC from its polynomial and reflection (crcmod's layout: for a
    reflected CRC, entry i is i's byte shifted out right through the reflected polynomial)."""
    width = spec.width_bits
    if width not in _CRC_WIDTHS:
        raise UsageError(f"CRC {spec.name}: a {width}-bit CRC cannot be dissected (8, 16, 24, 32)")
    mask = (1 << width) - 1
    poly = spec.poly & mask
    table = []
    if spec.reflect:
        rpoly = int(f"{poly:0{width}b}"[::-1], 2)
        for i in range(256):
            reg = i
            for _ in range(8):
                reg = (reg >> 1) ^ rpoly if reg & 1 else reg >> 1
            table.append(reg)
    else:
        top = 1 << (width - 1)
        for i in range(256):
            reg = i << (width - 8)
            for _ in range(8):
                reg = ((reg << 1) ^ poly) & mask if reg & top else (reg << 1) & mask
            table.append(reg)
    return table


class FieldData(TypedDict):
    """A payload field or a header field (with its offset) for the Lua engine."""

    name: str
    size: int
    offset: NotRequired[int]


class OpcodeData(TypedDict):
    """An opcode for the Lua engine: its payload layout, sub-opcode and reason names."""

    name: str
    fields: list[FieldData]
    fixed_size: int
    statuses: bool
    control: bool
    subs: dict[int, str]
    reasons: dict[int, str]
    items: NotRequired[list[FieldData]]
    item_size: NotRequired[int]


CrcData = TypedDict(
    "CrcData",
    {
        "name": str, "width": int, "mask": int, "reflect": bool, "init": int, "xor_out": int,
        "check": int | None, "table": list[int], "first": str, "last": str,
        "from": int,  # where the CRC's span starts (a keyword: no class syntax)
        "to_header": int | None, "size": int, "pad": int,
    },
)  # fmt: skip
"""A profile's CRC for the Lua engine: the Rocksoft model, its table and the span it covers."""


class ProfileData(TypedDict):
    """What the Lua engine needs of one profile (`profile_data`)."""

    name: str
    protocol: str
    description: str
    source: str
    stx: int
    etx: int | None
    little: bool
    header: list[FieldData]
    header_size: int
    fixed_counted: int
    max_len: int
    trailer_size: int
    seq_modulo: int
    crc: CrcData
    opcodes: dict[int, OpcodeData]
    nak_reasons: dict[int, str]


class ChartData(TypedDict):
    name: str
    codes: list[str]


class DissectorData(TypedDict):
    """The `KTCS` table: the profiles by name, which is each protocol's default, code names."""

    version: str
    garbage_hold: int
    order: list[str]
    defaults: dict[str, str]
    profiles: dict[str, ProfileData]
    chart: NotRequired[ChartData]


def _fields(specs: Iterable[FieldSpec]) -> list[FieldData]:
    return [{"name": f.name, "size": f.size} for f in specs]


def _opcode(o: Opcode) -> OpcodeData:
    out: OpcodeData = {
        "name": o.name,
        "fields": _fields(o.fields),
        "fixed_size": o.fixed_size,
        "statuses": o.statuses,
        "control": o.control,
        "subs": dict(o.subs),
        "reasons": dict(o.reasons),
    }
    if o.items:
        out["items"] = _fields(o.items)
        out["item_size"] = o.item_size
    return out


def profile_data(p: FrameProfile) -> ProfileData:
    """What the Lua engine needs of one profile, with the layout derived by FrameProfile itself."""
    header: list[FieldData] = [
        {"name": n, "size": s, "offset": p.offset_of(n)[0]} for n, s in p.header
    ]
    spec = p.crc_spec
    width = spec.width_bits
    to_header = None if p.crc_last == "data" else sum(p.offset_of(p.crc_last))
    return {
        "name": p.name,
        "protocol": p.protocol,
        "description": p.description,
        "source": Path(p.source).name,
        "stx": p.stx,
        "etx": p.etx,
        "little": p.little,
        "header": header,
        "header_size": p.header_size,
        "fixed_counted": p.fixed_counted,
        "max_len": p.max_len,
        "trailer_size": p.trailer_size,
        "seq_modulo": 1 << (8 * dict(p.header)["seq"]),
        "crc": {
            "name": spec.name,
            "width": width,
            "mask": (1 << width) - 1,
            "reflect": spec.reflect,
            "init": spec.init,
            "xor_out": spec.xor_out,
            "check": spec.check,
            "table": crc_table(spec),
            "first": p.crc_first,
            "last": p.crc_last,
            "from": p.offset_of(p.crc_first)[0],
            "to_header": to_header,
            "size": p.crc_size,
            "pad": p.crc_pad,
        },
        "opcodes": {op: _opcode(o) for op, o in sorted(p.opcodes.by_op.items())},
        "nak_reasons": dict(p.nak_reasons),
    }


# -- Lua literals ------------------------------------------------------------------------------

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_LUA_KEYWORDS = frozenset(
    "and break do else elseif end false for function goto if in local nil not or repeat return "
    "then true until while".split()
)


def lua_string(s: str) -> str:
    out = []
    for ch in s:
        if ch in ('"', "\\"):
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ord(ch) < 32 or ord(ch) == 127:
            out.append(f"\\{ord(ch):03d}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _key(k: object) -> str:
    if isinstance(k, str):
        return k if _IDENT.match(k) and k not in _LUA_KEYWORDS else f"[{lua_string(k)}]"
    if isinstance(k, int) and not isinstance(k, bool):
        return f"[{k}]"
    raise UsageError(f"cannot write {k!r} as a Lua table key")


def lua_literal(value: object, indent: int = 0) -> str:
    """A Lua expression for plain data: None, bool, int, str, lists and mappings."""
    pad = "    " * (indent + 1)
    if value is None:
        return "nil"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return lua_string(value)
    if isinstance(value, Sequence):
        items = [lua_literal(v, indent + 1) for v in value]
        if len(value) > 16 and all(isinstance(v, int) for v in value):  # CRC tables, 8 a line
            items = [f"0x{v:04X}" for v in value]
            rows = [", ".join(items[k : k + 8]) for k in range(0, len(items), 8)]
            return "{\n" + "".join(f"{pad}{r},\n" for r in rows) + "    " * indent + "}"
        if sum(len(i) for i in items) < 80 and "\n" not in "".join(items):
            return "{ " + ", ".join(items) + " }"
        return "{\n" + "".join(f"{pad}{i},\n" for i in items) + "    " * indent + "}"
    if isinstance(value, Mapping):
        entries = [
            f"{_key(k)} = {lua_literal(v, indent + 1)}" for k, v in value.items() if v is not None
        ]
        if not entries:
            return "{}"
        if sum(len(e) for e in entries) < 80 and "\n" not in "".join(entries):
            return "{ " + ", ".join(entries) + " }"
        return "{\n" + "".join(f"{pad}{e},\n" for e in entries) + "    " * indent + "}"
    raise UsageError(f"cannot write {type(value).__name__} as Lua")


# -- the dissector -----------------------------------------------------------------------------


def template() -> str:
    return resources.files("ktcs_bench.dissector").joinpath("ktcs.lua").read_text(encoding="utf-8")


def generate(profiles: Sequence[FrameProfile], chart: CodeChart | None = None) -> str:
    """The whole dissector for `profiles` (each protocol's default profile is the bench's, or the
    first of that protocol given), with code names from `chart`."""
    names = [p.name for p in profiles]
    if len(set(names)) != len(names):
        raise UsageError(f"two profiles share a name: {', '.join(names)}")
    defaults: dict[str, str] = {}
    for protocol in ("type1", "type2"):
        mine = [p.name for p in profiles if p.protocol == protocol]
        if not mine:
            raise UsageError(f"the dissector needs at least one {protocol} profile")
        bench = DEFAULT_PROFILE[protocol]
        defaults[protocol] = bench if bench in mine else mine[0]
    data: DissectorData = {
        "version": __version__,
        "garbage_hold": GARBAGE_HOLD,
        "order": names,
        "defaults": defaults,
        "profiles": {p.name: profile_data(p) for p in profiles},
    }
    if chart is not None:
        data["chart"] = {"name": chart.name, "codes": [c.name for c in chart.codes]}
    listing = "; ".join(f"{p.name} ({p.protocol}, {Path(p.source).name})" for p in profiles)
    head = (
        f"-- Generated by ktcs-bench {__version__} `ktcs-bench dissector` from: {listing}"
        + (f"; code names from chart {chart.name}" if chart else "")
        + ".\nlocal KTCS = "
        + lua_literal(data)
    )
    text = template()
    if DATA_MARK not in text:
        raise UsageError("the dissector template has lost its data mark")
    return text.replace(DATA_MARK, head, 1)


# -- where Wireshark looks ---------------------------------------------------------------------


def personal_lua_plugins(tshark: str = "tshark") -> Path:
    """The personal Lua plugin folder, as `tshark -G folders` names it."""
    exe = shutil.which(tshark)
    if exe is None:
        raise UsageError(
            f"{tshark} not found: install Wireshark/tshark, or write the file with --out"
        )
    try:
        out = subprocess.run(
            [exe, "-G", "folders"], capture_output=True, text=True, timeout=60, check=False
        ).stdout
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise UsageError(f"cannot ask {exe} for its folders: {exc}") from None
    for line in out.splitlines():
        label, _, value = line.partition(":")
        if label.strip().lower() == "personal lua plugins" and value.strip():
            return Path(value.strip())
    raise UsageError(f"`{exe} -G folders` names no personal Lua plugin folder")
