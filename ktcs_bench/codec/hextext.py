"""Hex text in the forms engineers paste -> byte chunks with their origin (line, time, direction).

Accepted, mixed freely: `<02><04>` (seed 004 Fig. 7 receive), `[02][84]` (its send lines, wrapped
over several lines), `02 04 00`, `020400`, `0x02,0x04`, console prefixes (`수신 =`, `송신 =`, `RX:`,
`TX:`), the bench's own hex log (`<seconds> <direction> <hex>`) and dumps: `xxd`, `hexdump -C`
and `od -t x1` (any `-A`). A dump's offset column is not data; its `*` line (repeated lines left
out) is expanded from the offsets around it, whatever their radix (od's octal or decimal, hex).
Dumps in 2-byte words (`od`, `od -x`, plain `hexdump`) are in the host's byte order, which the
text does not tell: their lines are skipped and counted (`word_dump_lines`), never guessed.
Other lines that are not hex (console annotations such as "Packet = [F1]-[E7], Cal = [00]-[00]")
are skipped and counted. Every chunk keeps its byte offset in the decoded stream.

`HexTextParser` takes one line at a time and keeps nothing but the current record's origin, so a
file of any size is parsed in bounded memory; `parse_hex_text` is the whole-text convenience.
`text_encoding` tells how a capture file's bytes are text (UTF-8, or CP949/EUC-KR as Korean
consoles save it), or that they are not text at all.
"""

from __future__ import annotations

import codecs
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

_PREFIX = re.compile(r"^\s*(수신|송신|rx|tx|recv|send|in|out)\s*[=:>]\s*", re.IGNORECASE)
_DIRECTION = {"수신": "rx", "송신": "tx", "recv": "rx", "send": "tx", "in": "rx", "out": "tx"}
_HEXLOG = re.compile(r"^\s*(\d+(?:\.\d+)?)\s+([A-Za-z][\w.>-]*)\s+(.*)$")
_XXD = re.compile(r"^\s*([0-9a-fA-F]{4,16}):\s+(.*)$")
# hexdump -C / od -t x1 [z]: an offset column, byte columns, maybe |ascii| or >ascii<
_BYTE_DUMP = re.compile(
    r"^\s*([0-9a-fA-F]{6,16})((?:\s{1,2}[0-9a-fA-F]{2})+)\s*(?:\|.*\||>.*<)?\s*$"
)
# od (octal words), od -x, plain hexdump: 2-byte words in host order
_WORD_DUMP = re.compile(r"^\s*[0-9a-fA-F]{6,16}(?:\s+(?:[0-9a-fA-F]{4}|[0-7]{6}))+\s*$")
_OFFSET_ONLY = re.compile(r"^\s*([0-9a-fA-F]{4,16}):?\s*$")
_TOKEN = re.compile(
    r"<([0-9a-fA-F]{2})>|\[([0-9a-fA-F]{2})\]|0[xX]([0-9a-fA-F]{1,2})(?![0-9a-fA-F])|([0-9a-fA-F]+)"
)
_SEPARATORS = re.compile(r"^[\s,;]*$")
_HEXWORD = re.compile(r"[0-9a-fA-F]+")
_HEXDIGITS = frozenset("0123456789abcdefABCDEF")

# a repeated dump line is expanded in pieces of at most this many bytes (never one allocation
# sized by an offset read from the text)
REPEAT_PIECE = 1 << 16
# how many skipped line numbers a streaming parser remembers (the count is always exact)
KEEP_SKIPPED = 100


@dataclass(slots=True)
class Chunk:
    """Bytes parsed from one record of the text, where they start in the stream, and their origin.
    A streaming parser leaves `data` empty: its bytes go straight to the caller."""

    offset: int
    data: bytearray
    line: int
    direction: str | None = None
    time: float | None = None


@dataclass
class HexText:
    chunks: list[Chunk] = field(default_factory=list)
    skipped_lines: list[int] = field(default_factory=list)
    word_dump_lines: int = 0

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


@dataclass
class _Dump:
    """The dump being read: its offset column's width, the radices its offsets are consistent
    with so far, the last line's offset and bytes, and whether a `*` followed that line."""

    width: int
    radices: tuple[int, ...]
    offset: str
    data: bytes
    repeat: bool = False


def _radices(token: str, width: int) -> tuple[int, ...]:
    """Radices an offset column may be in, most likely first: 7 digits is od's default (octal)."""
    order = (8, 16, 10) if width == 7 else (16, 8, 10)
    out = []
    for r in order:
        try:
            int(token, r)
        except ValueError:
            continue
        out.append(r)
    return tuple(out)


_NOTHING: tuple[bytes, ...] = ()


class HexTextParser:
    """Hex text one line at a time. `feed(line)` returns the bytes the line adds (an iterable of
    pieces, usually one); `chunk` is the record they belong to, `new_chunk` says whether this
    line began it. Nothing is kept of the bytes, so memory does not grow with the text."""

    def __init__(self) -> None:
        self.offset = 0
        self.lineno = 0
        self.chunk: Chunk | None = None
        self.new_chunk = False
        self.chunks = 0  # records begun so far
        self.skipped = 0
        self.skipped_lines: list[int] = []
        self.keep_skipped: int | None = KEEP_SKIPPED  # None: remember every skipped line
        self.word_dump_lines = 0
        self._dump: _Dump | None = None

    def feed(self, line: str) -> Iterable[bytes]:
        self.lineno += 1
        self.new_chunk = False
        body = line.split("#", 1)[0] if "#" in line else line
        # fast path: spaced bytes or one compact word, as `encode` prints them (one compact word
        # after a dump is its closing offset, handled below)
        if body[2:3] == " " or (self._dump is None and " " not in body):
            try:
                data = bytes.fromhex(body)
            except ValueError:
                pass
            else:
                if not data:  # a blank line
                    return _NOTHING
                self._dump = None
                return self._add(data, False, None, None)
        m = _HEXLOG.match(body)  # the bench's own hex log: what bulk files hold
        if m is not None:
            seconds, name, rest = m.groups()
            if not _HEXWORD.fullmatch(name):
                try:
                    data = bytes.fromhex(rest)
                except ValueError:
                    pass
                else:  # inline: this is the line bulk captures are made of
                    self._dump = None
                    self.chunk = Chunk(self.offset, bytearray(), self.lineno, name, float(seconds))
                    self.new_chunk = True
                    self.chunks += 1
                    self.offset += len(data)
                    return (data,)
        stripped = body.strip()
        if not stripped:
            return _NOTHING
        direction: str | None = None
        time: float | None = None
        starts_record = False
        if m is not None and not _HEXWORD.fullmatch(m.group(2)):
            time, direction, body = float(m.group(1)), m.group(2), m.group(3)
            starts_record = True
        elif m := _PREFIX.match(body):
            word = m.group(1).lower()
            direction = _DIRECTION.get(m.group(1), _DIRECTION.get(word, word))
            body = body[m.end() :]
            starts_record = True
        else:
            dumped = self._dump_line(body, stripped)
            if dumped is not None:
                return dumped
        self._dump = None
        parsed = hex_bytes(body)
        if parsed is None:
            return self._skip()
        return self._add(parsed, starts_record, direction, time)

    # -- internals ---------------------------------------------------------------------------
    def _add(
        self, data: bytes, starts_record: bool, direction: str | None, time: float | None
    ) -> Iterable[bytes]:
        if self.chunk is None or starts_record:
            self.chunk = Chunk(self.offset, bytearray(), self.lineno, direction, time)
            self.new_chunk = True
            self.chunks += 1
        self.offset += len(data)
        return (data,)

    def _skip(self) -> Iterable[bytes]:
        self.skipped += 1
        if self.keep_skipped is None or len(self.skipped_lines) < self.keep_skipped:
            self.skipped_lines.append(self.lineno)
        self.chunk = None
        return _NOTHING

    def _dump_line(self, body: str, stripped: str) -> Iterable[bytes] | None:
        """A line of a dump (bytes, `*`, the closing offset, or a word dump), or None."""
        d = self._dump
        if stripped == "*":
            if d is None:
                return self._skip()
            d.repeat = True
            return _NOTHING
        if m := _BYTE_DUMP.match(body):
            return self._dump_data(m.group(1), bytes.fromhex(m.group(2)), xxd=False)
        if m := _XXD.match(body):
            data = hex_bytes(m.group(2).split("  ", 1)[0])
            if data is None:
                return None
            return self._dump_data(m.group(1), data, xxd=True)
        if d is not None and (m := _OFFSET_ONLY.match(body)):
            pieces = self._repeats(d, m.group(1))
            self._dump = None
            return pieces
        if _WORD_DUMP.match(body):
            self.word_dump_lines += 1
            self._dump = None
            return self._skip()
        return None

    def _dump_data(self, token: str, data: bytes, xxd: bool) -> Iterable[bytes]:
        d = self._dump
        width = len(token) + (100 if xxd else 0)  # an xxd dump is never an od one
        pieces: Iterable[bytes] = _NOTHING
        if d is None or d.width != width:
            radices = (16,) if xxd else _radices(token, len(token))
            self._dump = _Dump(width, radices, token, data)
        else:
            pieces = self._repeats(d, token)
            d.offset, d.data, d.repeat = token, data, False
        if not data:
            return pieces
        self._add(data, False, None, None)
        if pieces is _NOTHING:
            return (data,)
        return _chain(pieces, data)

    def _repeats(self, d: _Dump, token: str) -> Iterable[bytes]:
        """The lines a `*` left out before the line at offset `token`, and narrow the radices."""
        size = len(d.data)

        def gap(r: int) -> int | None:
            try:
                g = int(token, r) - int(d.offset, r) - size
            except ValueError:
                return None
            ok = g == 0 or (d.repeat and size > 0 and g > 0 and g % size == 0)
            return g if ok else None

        fits = tuple(r for r in d.radices if gap(r) is not None)
        d.radices = fits or _radices(token, len(token))
        if not d.repeat or not fits or not size:
            return _NOTHING
        missing = gap(fits[0]) or 0
        self.offset += missing
        return _repeat(d.data, missing)


def _repeat(line: bytes, total: int) -> Iterator[bytes]:
    per = max(1, REPEAT_PIECE // len(line)) * len(line)
    block = line * (per // len(line))
    while total > 0:
        n = min(total, per)
        yield block if n == per else block[:n]
        total -= n


def _chain(pieces: Iterable[bytes], last: bytes) -> Iterator[bytes]:
    yield from pieces
    yield last


def parse_hex_text(text: str) -> HexText:
    """Parse a whole text. A prefixed console line starts a record; bare hex lines continue it."""
    result = HexText()
    parser = HexTextParser()
    parser.keep_skipped = None
    feed = parser.feed
    chunks = result.chunks
    for line in text.splitlines():
        pieces = feed(line)
        chunk = parser.chunk
        if chunk is None:
            continue
        if parser.new_chunk:
            chunks.append(chunk)
        data = chunk.data
        for piece in pieces:
            data += piece
    result.skipped_lines = parser.skipped_lines
    result.word_dump_lines = parser.word_dump_lines
    return result


# -- text files ----------------------------------------------------------------------------------
# bytes that never occur in text (NUL and the C0 controls other than \t \n \v \f \r and ESC)
_BINARY_BYTES = bytes(b for b in range(32) if b not in (9, 10, 11, 12, 13, 27))
_BINARY_RE = re.compile(b"[" + re.escape(_BINARY_BYTES) + b"]")
BINARY_SHARE = 0.05  # a window with more control bytes than this is not text
TEXT_WINDOW = 1 << 16  # text is judged 64 KiB at a time: the head, then every window after it


def _binary(window: bytes | bytearray) -> bool:
    """Whether a window of an ASCII-compatible text is binary: a NUL, or too many controls."""
    if b"\0" in window:
        return True
    controls = len(window) - len(window.translate(None, _BINARY_BYTES))
    return bool(window) and controls / len(window) > BINARY_SHARE


def text_encoding(head: bytes) -> str | None:
    """How bytes that begin with `head` are text: "utf-8" (with or without its BOM), "utf-16"
    (with a BOM), "cp949" (Korean consoles' EUC-KR and its extension, where UTF-8 fails), or
    None when they are binary. A head cut in the middle of a character is fine."""
    if head.startswith(codecs.BOM_UTF8):
        return "utf-8-sig"
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return "utf-16"
    if _binary(head):
        return None
    for encoding in ("utf-8", "cp949"):
        try:
            codecs.getincrementaldecoder(encoding)().decode(head, final=False)
        except UnicodeDecodeError:
            continue
        return encoding
    return "utf-8"  # mostly text with a stray byte or two: decoded with replacement characters


class TextWatch:
    """Where a stream that began as text stops being text, watched as it streams: every 64 KiB
    window after the head is judged by the head's rule (a NUL, or more than 5 % control bytes),
    so a capture with a binary tail is refused however long its text head, in memory bounded by
    two windows.

    `feed(block)` and `close()` return the stream offset of the first NUL or control byte of the
    first window found binary, None while the stream is text. Blocks may be of any size; windows
    are aligned at the stream's start (the first is the head `text_encoding` judged), each judged
    once complete; the last, partial one is judged at `close()` with the end of the window
    before it, never on a handful of bytes alone. UTF-8 and CP949 are ASCII-compatible (a control
    byte is never part of a character), so their bytes are judged as they are; UTF-16 is judged
    on its text, a character a unit, its offsets counted two bytes a character past the BOM."""

    def __init__(self, encoding: str) -> None:
        self._decoder = (
            codecs.getincrementaldecoder(encoding)(errors="replace")
            if encoding == "utf-16"
            else None
        )
        self._window = bytearray()  # the window being filled
        self._previous = b""  # the last complete window, for the partial one at the end
        self._at = 0  # stream offset (in units) of _window[0]

    def feed(self, block: bytes | bytearray) -> int | None:
        if self._decoder is not None:
            block = _units(self._decoder.decode(block))
        window = self._window
        pos, size = 0, len(block)
        while pos < size:
            take = min(TEXT_WINDOW - len(window), size - pos)
            window += block[pos : pos + take]
            pos += take
            if len(window) == TEXT_WINDOW:
                if _binary(window):
                    return self._offset(window, self._at)
                self._previous = bytes(window)
                self._at += TEXT_WINDOW
                window.clear()
        return None

    def close(self) -> int | None:
        if self._decoder is not None:
            found = self.feed(_units(self._decoder.decode(b"", final=True)))
            if found is not None:
                return found
        window = self._window
        if not window:
            return None
        keep = min(TEXT_WINDOW - len(window), len(self._previous))
        last = self._previous[len(self._previous) - keep :] + window
        return self._offset(last, self._at - keep) if _binary(last) else None

    def _offset(self, window: bytes | bytearray, start: int) -> int:
        """The stream offset of the first NUL or control byte of a window starting at `start`."""
        m = _BINARY_RE.search(window)
        units = start + (0 if m is None else m.start())
        return units if self._decoder is None else len(codecs.BOM_UTF16) + 2 * units


def _units(text: str) -> bytes:
    """Text as one byte a character, controls and NUL as themselves (UTF-16, to be judged)."""
    return text.encode("latin-1", errors="replace")


def binary_from(data: bytes, encoding: str) -> int | None:
    """Where a whole text in `encoding` stops being text (`TextWatch`'s rule), None if never."""
    watch = TextWatch(encoding)
    found = watch.feed(data)
    return found if found is not None else watch.close()


def decode_text(data: bytes) -> str | None:
    """A whole file's bytes as text in the encoding `text_encoding` finds; None if binary, at
    its head or anywhere after it."""
    encoding = text_encoding(data[:TEXT_WINDOW])
    if encoding is None or binary_from(data, encoding) is not None:
        return None
    return data.decode(encoding, errors="replace")
