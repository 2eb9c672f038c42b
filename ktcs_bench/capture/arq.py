"""ARQ events inferred from a link's frames, as a monitor sees them (pure; frames + time in).

Per direction it remembers the last data frame (SEQ, bytes, when) and reports:
* `retransmission of SEQ 0x10 (transmission 2)` -- the same SEQ and bytes seen again;
* `SEQ 0x10 repeated with different content`, `SEQ gap: expected 0x11, got 0x13`;
* `ACK of SEQ 0x10 after 19.4 ms` (Type I) -- matched to the other direction's outstanding frame;
* `NAK reason 1 (CRC error) for SEQ 0x11 -- expect a retransmission`;
* `bad frame (crc): the receiver should NAK it`.
ACK and NAK are never acknowledged, so they take no part in SEQ tracking (SPEC §3.3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ktcs_bench.capture.records import reverse_direction
from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import FrameProfile


@dataclass
class _Last:
    seq: int
    raw: bytes
    time: float | None
    count: int = 1
    acked: bool = False


@dataclass
class ArqTracker:
    profile: FrameProfile
    _last: dict[str, _Last] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._modulo = 1 << (8 * dict(self.profile.header)["seq"])

    def observe(self, direction: str, frame: Frame, time: float | None) -> list[str]:
        if frame.error is not None:
            if frame.error == "truncated":
                return ["incomplete frame: the receiver should NAK it after ΔR (reason 2)"]
            return [f"bad frame ({frame.error}): the receiver should NAK it"]
        if frame.seq is None or frame.op is None:
            return []
        opcode = self.profile.opcodes.get(frame.op)
        name = opcode.name if opcode else None
        if name == "ACK":
            return [self._ack(direction, frame.seq, time)]
        if name == "NAK":
            if self.profile.has_sub:  # Type II: the reason is SUB, DATA is the refused SEQ
                reason, seq = frame.sub, frame.data[0] if frame.data else frame.seq
            else:
                reason, seq = (frame.data[0] if frame.data else None), frame.seq
            what = "" if reason is None else f"reason {reason} ({self._reason(reason)}) "
            return [f"NAK {what}for SEQ 0x{seq:02X} -- expect a retransmission"]
        return self._data(direction, frame, time)

    def _reason(self, reason: int) -> str:
        return self.profile.nak_reason_name(reason)

    def _ack(self, direction: str, seq: int, time: float | None) -> str:
        out = self._last.get(reverse_direction(direction))
        if out is None or out.seq != seq:
            return f"ACK of SEQ 0x{seq:02X} (no such frame outstanding)"
        again = " again" if out.acked else ""
        out.acked = True
        if time is not None and out.time is not None:
            return f"ACK{again} of SEQ 0x{seq:02X} after {1000 * (time - out.time):.1f} ms"
        return f"ACK{again} of SEQ 0x{seq:02X}"

    def _data(self, direction: str, frame: Frame, time: float | None) -> list[str]:
        assert frame.seq is not None
        seq, last = frame.seq, self._last.get(direction)
        events: list[str] = []
        if last is not None and last.seq == seq:
            last.count += 1
            if last.raw == frame.raw:
                events.append(f"retransmission of SEQ 0x{seq:02X} (transmission {last.count})")
            else:
                events.append(f"SEQ 0x{seq:02X} repeated with different content")
            last.raw, last.acked = frame.raw, False
            return events
        if last is not None and seq != (last.seq + 1) % self._modulo:
            expected = (last.seq + 1) % self._modulo
            events.append(f"SEQ gap: expected 0x{expected:02X}, got 0x{seq:02X}")
        self._last[direction] = _Last(seq, frame.raw, time)
        return events
