"""The bench's hex log: one frame a line, `<seconds> <direction> <hex>`, with `#` header comments.

    # ktcs-bench hex log v1: <seconds since start> <direction> <frame bytes in hex>
    # start: 1712345678.123456
    # profile: ktcs-type1
    0.000000 ixl>atc 02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03
    0.019375 atc>ixl 02 00 00 10 06 00 03 87 00 00 03

Lines are exactly what `ktcs_bench.codec.hextext` reads, so `ktcs-bench decode LOG` works on a log.
`format_*` and `parse_hex_log` are pure; `HexLogWriter` only writes lines to a text stream.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TextIO

from ktcs_bench.capture.records import CaptureRecord, valid_direction
from ktcs_bench.codec.hextext import parse_hex_text
from ktcs_bench.errors import UsageError

MAGIC = "# ktcs-bench hex log v1"
_HEADER = re.compile(r"^#\s*([\w-]+)\s*:\s*(\S+)")


@dataclass
class HexLog:
    """A parsed hex log (or any hex text): records in file order and the header values."""

    records: list[CaptureRecord] = field(default_factory=list)
    start: float | None = None
    profile: str | None = None
    link: str | None = None


def format_header(start: float | None, profile: str | None = None, link: str | None = None) -> str:
    lines = [f"{MAGIC}: <seconds since start> <direction> <frame bytes in hex>"]
    if start is not None:
        lines.append(f"# start: {start:.6f}")
    if profile:
        lines.append(f"# profile: {profile}")
    if link:
        lines.append(f"# link: {link}")
    return "\n".join(lines) + "\n"


def format_line(record: CaptureRecord, start: float = 0.0) -> str:
    """One log line. Times before `start` are written as 0 (the format has no negative times)."""
    if not valid_direction(record.direction):
        raise UsageError(f"direction {record.direction!r} cannot be written to a hex log")
    t = max(0.0, (record.time if record.time is not None else start) - start)
    return f"{t:.6f} {record.direction} {record.data.hex(' ').upper()}\n"


def parse_hex_log(text: str) -> HexLog:
    """Records from a hex log -- or from any hex text `decode` accepts (console captures, dumps).

    Times are absolute (start + seconds) when the log has a `# start:` header, else relative;
    records from text without times have time None and direction `rx`/`tx`/`-`.
    """
    log = HexLog()
    for line in text.splitlines():
        m = _HEADER.match(line)
        if not m:
            continue
        key, value = m.group(1).lower(), m.group(2)
        if key == "start":
            try:
                log.start = float(value)
            except ValueError:
                raise UsageError(f"bad start time in hex log header: {value!r}") from None
        elif key == "profile":
            log.profile = value
        elif key == "link":
            log.link = value
    base = log.start or 0.0
    for chunk in parse_hex_text(text).chunks:
        time = None if chunk.time is None else base + chunk.time
        log.records.append(CaptureRecord(time, chunk.direction or "-", bytes(chunk.data)))
    return log


class HexLogWriter:
    """Writes records as hex-log lines. Times are relative to `start` (default: the first record)."""

    def __init__(
        self,
        stream: TextIO,
        *,
        start: float | None = None,
        profile: str | None = None,
        link: str | None = None,
        close_stream: bool = False,
    ) -> None:
        self._stream = stream
        self._start = start
        self._profile = profile
        self._link = link
        self._close_stream = close_stream
        self._header_done = False

    def write(self, record: CaptureRecord) -> None:
        if not self._header_done:
            if self._start is None:
                self._start = record.time if record.time is not None else 0.0
            self._stream.write(format_header(self._start, self._profile, self._link))
            self._header_done = True
        self._stream.write(format_line(record, self._start or 0.0))
        self._stream.flush()

    def set_endpoint(self, name: str, host: str, port: int) -> None:
        """A hex log names the ends by direction only: their addresses are not kept."""

    def flush(self) -> None:
        self._stream.flush()

    def close(self) -> None:
        if not self._header_done:
            self._stream.write(format_header(self._start, self._profile, self._link))
            self._header_done = True
        self._stream.flush()
        if self._close_stream:
            self._stream.close()
