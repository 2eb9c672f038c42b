"""Captures behind one front (python-can's Logger/LogReader shape): hex logs and pcapng.

Owns: the capture record, the hex-log and pcapng formats (pure encode/parse functions) and thin
file writers/readers chosen by the file name (`.pcapng` -> pcapng, anything else -> hex log), and
the printer of decoded records (`printer`: text or JSON lines, for `monitor` and `replay`).
Must not touch: sockets, ptys, clocks -- records arrive with their time already set (the printer
formats it, never reads one).

    with open_writer("link.pcapng", link="type1") as w:
        w.write(CaptureRecord(time.time(), "ixl>atc", frame))
    capture = read_capture("link.hex")      # .records, .profile, .link, .start
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, Protocol

from ktcs_bench.capture.hexlog import HexLogWriter, parse_hex_log
from ktcs_bench.capture.pcapng import PcapngEncoder, is_pcapng, parse_pcapng
from ktcs_bench.capture.records import (
    CaptureRecord,
    normalise_direction,
    reverse_direction,
    split_direction,
    valid_direction,
)
from ktcs_bench.codec.hextext import decode_text
from ktcs_bench.errors import UsageError

__all__ = [
    "Capture",
    "CaptureRecord",
    "CaptureWriter",
    "HexLogWriter",
    "PcapngWriter",
    "normalise_direction",
    "open_writer",
    "read_capture",
    "reverse_direction",
    "split_direction",
    "valid_direction",
]


class CaptureWriter(Protocol):
    def write(self, record: CaptureRecord) -> None: ...

    def set_endpoint(self, name: str, host: str, port: int) -> None:
        """The real address of end `name` for the records that follow (a TCP tap knows it)."""

    def close(self) -> None: ...


class PcapngWriter:
    """Writes records to a binary stream as pcapng (see `ktcs_bench.capture.pcapng`)."""

    def __init__(
        self,
        stream: BinaryIO,
        *,
        link: str = "type1",
        endpoints: Mapping[str, tuple[str, int]] | None = None,
        close_stream: bool = False,
        flush_each: bool = True,
    ) -> None:
        self._stream = stream
        self._flush_each = flush_each  # live: readable as it grows; a virtual run: at the end
        self.encoder = PcapngEncoder(link, endpoints)
        self._close_stream = close_stream
        self._stream.write(self.encoder.start())
        self._stream.flush()

    def write(self, record: CaptureRecord) -> None:
        self._stream.write(self.encoder.encode(record))
        if self._flush_each:
            self._stream.flush()

    def set_endpoint(self, name: str, host: str, port: int) -> None:
        """The real address of Type II end `name` for the packets that follow."""
        self.encoder.set_endpoint(name, host, port)

    def flush(self) -> None:
        """Everything written so far onto the file (for a reader, mid-run)."""
        self._stream.flush()

    def close(self) -> None:
        self._stream.flush()
        if self._close_stream:
            self._stream.close()


class _Closing:
    """Context-manager wrapper so `with open_writer(...) as w:` closes the file."""

    def __init__(self, writer: HexLogWriter | PcapngWriter) -> None:
        self.writer = writer

    def write(self, record: CaptureRecord) -> None:
        self.writer.write(record)

    def set_endpoint(self, name: str, host: str, port: int) -> None:
        self.writer.set_endpoint(name, host, port)

    def flush(self) -> None:
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()

    def __enter__(self) -> _Closing:
        return self

    def __exit__(
        self, t: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def capture_kind(path: str | Path) -> str:
    """ "pcapng" for *.pcapng, else "hex"."""
    return "pcapng" if str(path).lower().endswith(".pcapng") else "hex"


def open_writer(
    path: str | Path,
    *,
    link: str = "type1",
    profile: str | None = None,
    start: float | None = None,
    endpoints: Mapping[str, tuple[str, int]] | None = None,
    flush_each: bool = True,
) -> _Closing:
    """A writer for `path`, the format chosen by its suffix; `link` is type1/type2 (pcapng).
    `flush_each`: pcapng is flushed after every record (off: when the buffer fills, and at the
    end -- a run on a virtual clock that nobody reads while it runs)."""
    try:
        if capture_kind(path) == "pcapng":
            return _Closing(
                PcapngWriter(
                    open(path, "wb"),
                    link=link,
                    endpoints=endpoints,
                    close_stream=True,
                    flush_each=flush_each,
                )  # fmt: skip
            )
        stream = open(path, "w", encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot write capture {path}: {exc.strerror}") from None
    return _Closing(
        HexLogWriter(stream, start=start, profile=profile, link=link, close_stream=True)
    )


@dataclass
class Capture:
    records: list[CaptureRecord] = field(default_factory=list)
    kind: str = "hex"
    profile: str | None = None
    link: str | None = None
    start: float | None = None

    @property
    def directions(self) -> list[str]:
        """Directions in order of first appearance."""
        seen: dict[str, None] = {}
        for r in self.records:
            seen.setdefault(r.direction, None)
        return list(seen)


def parse_capture(data: bytes, name: str = "the capture") -> Capture:
    """A capture from its bytes: pcapng by its magic, else hex text of any form `decode` reads
    (UTF-8 or CP949/EUC-KR). Bytes that are neither -- a binary file -- are refused, never taken
    for hex text and sent as garbage."""
    if is_pcapng(data):
        return Capture(parse_pcapng(data), "pcapng")
    text = decode_text(data)
    if text is None:
        raise UsageError(f"{name} is not a capture: neither pcapng nor hex text (a binary file?)")
    log = parse_hex_log(text)
    return Capture(log.records, "hex", log.profile, log.link, log.start)


def read_capture(path: str | Path) -> Capture:
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise UsageError(f"cannot read capture {path}: {exc.strerror}") from None
    return parse_capture(data, str(path))
