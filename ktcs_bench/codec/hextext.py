"""Hex text in the forms engineers paste -> byte chunks with their origin (line, time, direction).

Accepted, mixed freely: `<02><04>` (seed 004 Fig. 7 receive), `[02][84]` (its send lines, wrapped
over several lines), `02 04 00`, `020400`, `0x02,0x04`, xxd and `hexdump -C` dumps, console prefixes
(`수신 =`, `송신 =`, `RX:`, `TX:`), and the bench's own hex log (`<seconds> <direction> <hex>`).
Lines that are not hex (console annotations such as "Packet = [F1]-[E7], Cal = [00]-[00]") are
skipped and counted. Every chunk keeps its byte offset in the decoded stream.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

_PREFIX = re.compile(r"^\s*(수신|송신|rx|tx|recv|send|in|out)\s*[=:>]\s*", re.IGNORECASE)
_DIRECTION = {"수신": "rx", "송신": "tx", "recv": "rx", "send": "tx", "in": "rx", "out": "tx"}
_HEXLOG = re.compile(r"^\s*(\d+(?:\.\d+)?)\s+([A-Za-z][\w.>-]*)\s+(.*)$")
_XXD = re.compile(r"^\s*[0-9a-fA-F]{4,16}:\s+(.*)$")
_HEXDUMP_C = re.compile(r"^\s*[0-9a-fA-F]{8}\s{2}(.*?)\s*(\|.*\|)?\s*$")
_TOKEN = re.compile(
    r"<([0-9a-fA-F]{2})>|\[([0-9a-fA-F]{2})\]|0[xX]([0-9a-fA-F]{1,2})(?![0-9a-fA-F])|([0-9a-fA-F]+)"
)
_SEPARATORS = re.compile(r"^[\s,;]*$")
_HEXWORD = re.compile(r"[0-9a-fA-F]+")


@dataclass(slots=True)
class Chunk:
    """Bytes parsed from one record of the text, where they start in the stream, and their origin."""

    offset: int
    data: bytearray
    line: int
    direction: str | None = None
    time: float | None = None


@dataclass
class HexText:
    chunks: list[Chunk] = field(default_factory=list)
    skipped_lines: list[int] = field(default_factory=list)

    @property
    def data(self) -> bytes:
        return b"".join(bytes(c.data) for c in self.chunks)

    def origin(self, offset: int) -> Chunk | None:
        """The chunk holding stream byte `offset` (to label a frame with its line, time, direction)."""
        lo, hi = 0, len(self.chunks) - 1
        while lo <= hi:
            mid = (lo + hi) // 2
            c = self.chunks[mid]
            if offset < c.offset:
                hi = mid - 1
            elif offset >= c.offset + len(c.data):
                lo = mid + 1
            else:
                return c
        return None


def hex_bytes(text: str) -> bytes | None:
    """The bytes of one piece of hex text, or None when it is not purely hex."""
    try:  # fast path: "02 04 00" and "020400" (what the bench's own hex logs hold)
        return bytes.fromhex(text)
    except ValueError:
        pass
    out = bytearray()
    pos = 0
    for m in _TOKEN.finditer(text):
        if not _SEPARATORS.match(text[pos : m.start()]):
            return None
        pos = m.end()
        angle, square, prefixed, bare = m.groups()
        if bare is not None:
            if len(bare) % 2:
                return None
            out += bytes.fromhex(bare)
        else:
            out.append(int(angle or square or prefixed, 16))
    if not _SEPARATORS.match(text[pos:]):
        return None
    return bytes(out)


def parse_hex_text(text: str) -> HexText:
    """Parse a whole text. A prefixed console line starts a record; bare hex lines continue it."""
    result = HexText()
    offset = 0
    current: Chunk | None = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0] if "#" in line else line
        if not body or body.isspace():
            continue
        direction: str | None = None
        time: float | None = None
        starts_record = False
        m2 = _HEXLOG.match(body)  # the bench's own hex log first: it is what bulk files hold
        if m2 and not _HEXWORD.fullmatch(m2.group(2)):
            time, direction, body = float(m2.group(1)), m2.group(2), m2.group(3)
            starts_record = True
        elif m := _PREFIX.match(body):
            word = m.group(1).lower()
            direction = _DIRECTION.get(m.group(1), _DIRECTION.get(word, word))
            body = body[m.end() :]
            starts_record = True
        elif (m3 := _HEXDUMP_C.match(body)) and m3.group(2):
            body = m3.group(1)
        elif m4 := _XXD.match(body):
            body = m4.group(1).split("  ", 1)[0]
        data = hex_bytes(body)
        if data is None:
            result.skipped_lines.append(lineno)
            current = None
            continue
        if current is None or starts_record:
            current = Chunk(offset, bytearray(), lineno, direction, time)
            result.chunks.append(current)
        current.data += data
        offset += len(data)
    return result
