"""Records as text for people (the seed 004 Fig. 7 console style) and as JSON lines for programs.

Pure functions: a record (+ its profile and an optional code chart) in, a string or a dict out. The
JSON object has exactly the keys of SPEC §7; garbage is `{"garbage": hex, "offset": n}`.
"""

from __future__ import annotations

import json
from typing import Any, Literal, TypedDict

from ktcs_bench.codec.frame import Frame, Garbage, Record
from ktcs_bench.codec.opcodes import Opcode, PayloadError
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.station_codes.chart import CodeChart


class FrameJson(TypedDict):
    """A frame as a JSON line (SPEC §7): where, its header, DATA (hex) and its items, the CRC."""

    protocol: str
    profile: str
    offset: int
    seq: int | None
    op: int | None
    op_name: str | None
    sub: int | None
    data: str
    items: list[list[int]] | None
    crc_ok: bool
    crc_packet: int | None
    crc_calc: int | None
    error: str | None


class GarbageJson(TypedDict):
    """Bytes that are no frame, as a JSON line: their hex and where they start."""

    garbage: str
    offset: int


GREEN, RED, YELLOW, DIM, BOLD, RESET = (
    "\x1b[32m", "\x1b[31m", "\x1b[33m", "\x1b[2m", "\x1b[1m", "\x1b[0m"
)  # fmt: skip


def bracketed(raw: bytes, style: str = "[]", per_line: int = 18, indent: str = "  ") -> str:
    """Bytes as the console prints them, [02][84]... or <02><04>..., wrapped like Fig. 7."""
    a, b = style[0], style[1]
    cells = [f"{a}{x:02X}{b}" for x in raw]
    rows = ["".join(cells[k : k + per_line]) for k in range(0, len(cells), per_line)]
    return ("\n" + indent).join(rows)


def crc_words(frame: Frame, profile: FrameProfile) -> str:
    """The console's verdict: "Packet = [F1]-[E7], Cal = [F1]-[E7]" (low byte first)."""
    if frame.crc_packet is None or frame.crc_calc is None:
        return "Packet = [--]-[--], Cal = [--]-[--]"
    n = profile.crc_size
    order: Literal["little", "big"] = "little" if profile.little else "big"
    pk = "-".join(f"[{x:02X}]" for x in frame.crc_packet.to_bytes(n, order))
    ca = "-".join(f"[{x:02X}]" for x in frame.crc_calc.to_bytes(n, order))
    return f"Packet = {pk}, Cal = {ca}"


def payload(
    frame: Frame, profile: FrameProfile
) -> tuple[Opcode | None, dict[str, Any] | None, str | None]:
    """(opcode, parsed payload, payload error) of a frame that passed its framing checks."""
    if frame.op is None:
        return None, None, None
    opcode = profile.opcodes.get(frame.op)
    if opcode is None or frame.error is not None:
        return opcode, None, None
    try:
        return opcode, opcode.parse(frame.data), None
    except PayloadError as exc:
        return opcode, None, str(exc)


def to_json(record: Record, profile: FrameProfile) -> FrameJson | GarbageJson:
    if record.__class__ is Garbage:
        return {"garbage": record.raw.hex(), "offset": record.offset}
    assert isinstance(record, Frame)
    op = record.op
    opcode = None if op is None else profile.opcodes.by_op.get(op)
    error = record.error
    data = record.raw[record.data_start : record.data_end]
    items = None
    if opcode is not None and error is None:
        try:
            items = opcode.json_items(data)
        except PayloadError:
            error = "format"
    packet, calc = record.crc_packet, record.crc_calc
    return {
        "protocol": profile.protocol,
        "profile": profile.name,
        "offset": record.offset,
        "seq": record.seq,
        "op": op,
        "op_name": None if opcode is None else opcode.name,
        "sub": record.sub,
        "data": data.hex() if record.error != "length" else "",
        "items": items,
        "crc_ok": packet is not None and packet == calc,
        "crc_packet": packet,
        "crc_calc": calc,
        "error": error,
    }


# one encoder, made once: json.dumps with arguments builds a new one for every call
json_line = json.JSONEncoder(ensure_ascii=False, separators=(", ", ": ")).encode


def _paint(text: str, colour: str, on: bool) -> str:
    return f"{colour}{text}{RESET}" if on else text


def _code_label(chart: CodeChart | None, number: int) -> str:
    name = chart.name_of(number) if chart else None
    return f"{number} {name}" if name else str(number)


def to_text(
    record: Record,
    profile: FrameProfile,
    chart: CodeChart | None = None,
    colour: bool = False,
    label: str = "",
) -> str:
    """A multi-line console description: raw bytes, every field, payload, CRC verdict."""
    if isinstance(record, Garbage):
        head = f"@{record.offset} {label}garbage {len(record.raw)} bytes"
        return _paint(f"{head}\n  {bracketed(record.raw)}", DIM, colour)
    f = record
    opcode, parsed, perr = payload(f, profile)
    lines = []
    verdict = (
        _paint("CRC OK", GREEN, colour) if f.error is None and perr is None
        else _paint("CRC OK, ERROR: format", RED, colour) if f.error is None
        else _paint(f"ERROR: {f.error}", RED, colour)
    )  # fmt: skip
    lines.append(
        f"@{f.offset} {label}{profile.protocol} {profile.name}  {len(f.raw)} bytes  {verdict}"
    )
    lines.append("  " + bracketed(f.raw))
    fields = [f"STX {f.raw[0]:02X}"]
    if f.seq is not None and f.op is not None:
        length = f.raw[1 : 1 + dict(profile.header)["len"]]
        fields.append(f"LEN {int.from_bytes(length, 'little' if profile.little else 'big')}")
        fields.append(f"SEQ 0x{f.seq:02X} ({f.seq})")
        name = opcode.name if opcode else "unknown"
        width = 2 * dict(profile.header)["op"]
        fields.append(f"OP 0x{f.op:0{width}X} {name}")
        if f.sub is not None:
            sname = opcode.sub_name(f.sub) if opcode else None
            fields.append(f"SUB {f.sub}" + (f" {sname}" if sname else ""))
    lines.append("  " + "  ".join(fields))
    if f.error is None or f.error == "crc":
        data = f.data
        lines.append(f"  DATA ({len(data)} bytes) {data.hex(' ').upper()}" if data else "  DATA -")
    if parsed:
        flat = [f"{k}={v}" for k, v in parsed.items() if k not in ("items", "statuses")]
        if opcode and opcode.reasons and "reason" in parsed:
            flat.append(f"({opcode.reasons.get(parsed['reason'], '?')})")
        if opcode and opcode.name == "NAK" and "reason" in parsed:
            flat.append(f"({profile.nak_reason_name(parsed['reason'])})")
        if opcode and opcode.name == "REQUEST_ALL" and "start" in parsed:
            last = parsed["start"] + parsed["count"] - 1
            flat.append(f"→ codes [{parsed['start']}]-[{last}]")
        if flat:
            lines.append("  " + " ".join(flat))
        items = parsed.get("items")
        if items:
            shown = ", ".join(f"{_code_label(chart, it[0])}={it[1]}" for it in items)
            lines.append(f"  items ({len(items)}): {shown}")
        statuses = parsed.get("statuses")
        if statuses is not None:
            if chart:
                shown = ", ".join(
                    f"{_code_label(chart, k + 1)}={s}" for k, s in enumerate(statuses)
                )
            else:
                shown = " ".join(str(s) for s in statuses)
            lines.append(f"  statuses ({len(statuses)} codes): {shown}")
    if perr:
        lines.append("  " + _paint(f"payload: {perr}", YELLOW, colour))
    if f.error == "truncated":
        need = ""
        if f.seq is not None:
            ln = int.from_bytes(f.raw[1 : 1 + dict(profile.header)["len"]],
                                "little" if profile.little else "big")  # fmt: skip
            need = f" of the {profile.frame_size(ln - profile.fixed_counted)} its LEN announces"
        lines.append(f"  truncated: {len(f.raw)} bytes{need}")
    lines.append("  " + crc_words(f, profile))
    return "\n".join(lines)
