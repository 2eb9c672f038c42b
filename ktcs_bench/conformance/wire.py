"""The suite's own end of the link, built from raw frames (`FrameCodec`, `StreamDecoder`) -- never
from our link code, so a case judges the device and not the bench.

`Type1Wire` talks over any serial transport (pyserial URL, device path, a pty's slave path);
`Type2Wire` over one TCP (or TLS) connection. Both record every frame, both directions, with its
time since the case began (`Evidence`), and both are plain blocking code driven by the case.
While a case times the device's reaction to silence (`silent()`), the suite's end sends nothing --
not even an ACK -- and a send there is the suite breaking the case's premise (`Inconclusive`).
"""

from __future__ import annotations

import contextlib
import random
import socket
import ssl
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from ktcs_bench.codec import Frame, FrameCodec, FrameProfile, Garbage, Record, StreamDecoder
from ktcs_bench.errors import PeerError
from ktcs_bench.transport.base import Transport, TransportClosed

SUITE, DEVICE = "suite>device", "device>suite"


class Inconclusive(Exception):
    """The suite itself broke the premise of the case (it sent while timing the device's silence):
    the verdict is error, never fail -- the device was not given the conditions the rule is about."""


@dataclass(slots=True)
class EvidenceRecord:
    time: float  # seconds since the case began
    direction: str
    hex: str
    summary: str

    def as_dict(self) -> dict[str, object]:
        return {"time": round(self.time, 6), "direction": self.direction, "hex": self.hex,
                "summary": self.summary}  # fmt: skip


@dataclass
class Evidence:
    """Every frame of one case, both directions, timestamped; and the checks made on them."""

    start: float = field(default_factory=time.monotonic)
    records: list[EvidenceRecord] = field(default_factory=list)
    checks: list[str] = field(default_factory=list)

    def add(self, direction: str, raw: bytes, summary: str, at: float | None = None) -> float:
        now = time.monotonic() if at is None else at
        self.records.append(EvidenceRecord(now - self.start, direction, raw.hex(" "), summary))
        return now

    def note(self, text: str) -> None:
        self.checks.append(text)


def summarize(profile: FrameProfile, rec: Record) -> str:
    if isinstance(rec, Garbage):
        return f"garbage ({len(rec.raw)} bytes)"
    op = profile.opcodes.get(rec.op) if rec.op is not None else None
    name = op.name if op else (f"op 0x{rec.op:04X}" if rec.op is not None else "?")
    parts = [name]
    if rec.seq is not None:
        parts.append(f"SEQ 0x{rec.seq:02X}")
    if rec.sub is not None and profile.has_sub:
        parts.append(f"sub {rec.sub}")
    if op is not None and op.name == "NAK" and rec.data and not profile.has_sub:
        parts.append(f"reason {rec.data[0]}")
    if op is not None and op.name == "NAK" and rec.data and profile.has_sub:
        parts.append(f"refused SEQ 0x{rec.data[0]:02X}")
    if rec.error:
        parts.append(f"ERROR {rec.error}")
    return " ".join(parts)


Arrival = tuple[float, Frame]  # (monotonic time, frame)


class _WireBase:
    def __init__(self, profile: FrameProfile) -> None:
        self.profile = profile
        self.codec = FrameCodec(profile)
        self.decoder = StreamDecoder(profile)
        self.evidence = Evidence()
        self.received: list[Arrival] = []  # every record of the current case that is a frame
        self.garbage = 0
        self.heard = 0  # bytes received from the device, ever (0: it never answered)
        self.closed = False  # the device's end is gone: no frame can come any more
        self._silence: tuple[str, bool] | None = None  # (what is being timed, ACKs allowed)
        ops = profile.opcodes.by_name
        self.op = {name: o.op for name, o in ops.items()}

    def begin(self, evidence: Evidence) -> None:
        self.evidence = evidence
        self.received = []

    def name_of(self, frame: Frame) -> str:
        op = self.profile.opcodes.get(frame.op) if frame.op is not None else None
        return op.name if op else "?"

    def _read(self, timeout: float) -> bytes:
        raise NotImplementedError

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _on_frame(self, now: float, frame: Frame) -> None:
        """Hook: a frame arrived (the Type I wire ACKs it here)."""

    def send_raw(self, data: bytes, summary: str | None = None) -> float:
        if summary is None:
            recs = StreamDecoder(self.profile).feed(data)
            summary = "; ".join(summarize(self.profile, r) for r in recs) or "partial frame"
        if self._silence is not None:
            raise Inconclusive(f"the suite sent {summary} while {self._silence[0]}")
        return self._transmit(data, summary)

    def _transmit(self, data: bytes, summary: str) -> float:
        self._write(data)
        return self.evidence.add(SUITE, data, summary)

    @contextlib.contextmanager
    def silent(self, why: str, acks: bool = False) -> Iterator[None]:
        """The suite sends nothing inside (with `acks`, nothing but ACKs of the device's frames):
        `why` names what the device is timing meanwhile. A send in here raises `Inconclusive`;
        the device's frames are acknowledged when the silence ends (Type I)."""
        self._silence = (why, acks)
        self.evidence.note(f"     the suite keeps silent ({why})")
        try:
            yield
        finally:
            self._silence = None
        self._after_silence()

    def _after_silence(self) -> None:
        """Hook: the silence is over (the Type I wire sends the ACK it held back)."""

    def poll(self, timeout: float) -> list[Arrival]:
        """Read for at most `timeout` s (returns as soon as something arrived)."""
        data = self._read(max(0.0, timeout))
        if not data:
            return []
        self.heard += len(data)
        now = time.monotonic()
        out: list[Arrival] = []
        for rec in self.decoder.feed(data):
            self.evidence.add(DEVICE, rec.raw, summarize(self.profile, rec), now)
            if isinstance(rec, Garbage):
                self.garbage += 1
                continue
            out.append((now, rec))
            self.received.append((now, rec))
            self._on_frame(now, rec)
        return out

    def wait_for(
        self, pred: Callable[[Frame], bool], timeout: float, since: int | None = None
    ) -> Arrival | None:
        """The first frame from the device satisfying `pred` within `timeout` s; with `since`
        (an index into `received`), frames already received from there on count too."""
        if since is not None:
            for arrival in self.received[since:]:
                if pred(arrival[1]):
                    return arrival
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0 or self.closed:
                return None
            for arrival in self.poll(min(left, 0.05)):
                if pred(arrival[1]):
                    return arrival

    def collect(self, duration: float) -> list[Arrival]:
        end = time.monotonic() + duration
        out: list[Arrival] = []
        while (left := end - time.monotonic()) > 0:
            out.extend(self.poll(min(left, 0.05)))
        return out


class Type1Wire(_WireBase):
    """The suite's end of a Type I link: raw frames, its own SEQ, optional automatic ACKs."""

    def __init__(self, transport: Transport, profile: FrameProfile) -> None:
        super().__init__(profile)
        self.transport = transport
        self.auto_ack = True
        self.ack_wait = 1.0  # how long settle() waits for an ACK (the runner sets it from timing)
        self._held: int | None = None  # SEQ of the device's last data frame while we kept silent
        # Start at a random SEQ: a device remembers the last SEQ it accepted from an earlier run.
        self.seq = random.randrange(self.codec.seq_modulo)

    def _read(self, timeout: float) -> bytes:
        try:
            return self.transport.recv(timeout)
        except TransportClosed as exc:
            raise PeerError(f"the device's line closed: {exc}") from exc

    def _write(self, data: bytes) -> None:
        try:
            self.transport.send(data)
        except TransportClosed as exc:
            raise PeerError(f"the device's line closed: {exc}") from exc

    def is_data(self, frame: Frame) -> bool:
        return frame.ok and frame.op not in (self.op["ACK"], self.op["NAK"])

    def _on_frame(self, now: float, frame: Frame) -> None:
        if self.auto_ack and self.is_data(frame):
            assert frame.seq is not None
            if self._silence is not None and not self._silence[1]:
                self._held = frame.seq  # stop-and-wait: the last one is the one outstanding
                return
            self._transmit(
                self.codec.encode(frame.seq, self.op["ACK"]), f"ACK SEQ 0x{frame.seq:02X}"
            )

    def _after_silence(self) -> None:
        seq, self._held = self._held, None
        if seq is not None and self.auto_ack:
            self.send_raw(
                self.codec.encode(seq, self.op["ACK"]), f"ACK SEQ 0x{seq:02X} (held while silent)"
            )

    def next_seq(self) -> int:
        self.seq = (self.seq + 1) % self.codec.seq_modulo
        return self.seq

    def frame(self, op: str | int, data: bytes = b"", seq: int | None = None) -> bytes:
        code = self.op[op] if isinstance(op, str) else op
        return self.codec.encode(self.next_seq() if seq is None else seq, code, data)

    def message(self, op: str, seq: int | None = None, **values: object) -> bytes:
        opcode = self.profile.opcodes.by_name[op]
        return self.frame(op, opcode.build(values), seq)

    def ack_of(self, seq: int) -> Callable[[Frame], bool]:
        return lambda f: f.ok and f.op == self.op["ACK"] and f.seq == seq

    def nak(self) -> Callable[[Frame], bool]:
        return lambda f: f.ok and f.op == self.op["NAK"]

    def settle(self, quiet: float = 0.15, limit: float = 3.0) -> None:
        """Bring the link to a known state: our LINK_TEST acknowledged, then the device quiet
        (everything it had queued -- a REQUEST_ALL after recovery, a LINK_TEST -- acknowledged)."""
        self.auto_ack = True
        end = time.monotonic() + limit
        for _ in range(2):
            seq = self.next_seq()
            self.send_raw(self.codec.encode(seq, self.op["LINK_TEST"]))
            if self.wait_for(self.ack_of(seq), self.ack_wait) is not None:
                break
        while time.monotonic() < end:
            if not self.poll(quiet):
                return

    def close(self) -> None:
        self.transport.close()


class Type2Wire(_WireBase):
    """The suite's end of one Type II connection."""

    def __init__(self, sock: socket.socket | ssl.SSLSocket, profile: FrameProfile) -> None:
        super().__init__(profile)
        self.sock = sock
        self.seq = 0
        sock.setblocking(True)

    def _read(self, timeout: float) -> bytes:
        if self.closed:
            time.sleep(min(timeout, 0.05))
            return b""
        self.sock.settimeout(max(timeout, 0.001))
        try:
            data = self.sock.recv(65536)
        except (TimeoutError, BlockingIOError):
            return b""
        except ssl.SSLWantReadError:
            return b""
        except (ConnectionError, OSError):
            data = b""
        if not data:
            self.closed = True
            self.evidence.note("the device closed the connection")
        return data

    def _write(self, data: bytes) -> None:
        try:
            self.sock.sendall(data)
        except (ConnectionError, OSError) as exc:
            raise PeerError(f"the device's connection failed: {exc}") from exc

    def frame(
        self, op: str | int, sub: int = 0, data: bytes = b"", seq: int | None = None
    ) -> bytes:
        code = self.op[op] if isinstance(op, str) else op
        if seq is None:
            seq, self.seq = self.seq, (self.seq + 1) % 256
        return self.codec.encode(seq, code, data, sub)

    def message(self, op: str, sub: int = 0, seq: int | None = None, **values: object) -> bytes:
        opcode = self.profile.opcodes.by_name[op]
        return self.frame(op, sub, opcode.build(values), seq)

    def wait_closed(self, timeout: float) -> float | None:
        """When the device closed the connection (monotonic), or None if it did not."""
        end = time.monotonic() + timeout
        while not self.closed:
            left = end - time.monotonic()
            if left <= 0:
                return None
            self.poll(min(left, 0.05))
        return time.monotonic()

    def close(self) -> None:
        self.closed = True
        try:
            self.sock.close()
        except OSError:
            pass
