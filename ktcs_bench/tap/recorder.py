"""What a tap saw, as timestamped frames: delivered bytes per direction in, capture records out.

Sans-I/O. Each direction is framed with the `StreamDecoder` of the link's profile, so a record is
one frame (or one span of garbage); a partial frame is reported as it stands once the direction
has been idle for `idle_flush` seconds (`handle_timer(now)` at `next_deadline()`: the timer shape
of `ktcs_bench.timed`). A record's time is when its last byte passed the tap.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ktcs_bench.capture.records import CaptureRecord
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.codec.stream import StreamDecoder

IDLE_FLUSH = 0.2


@dataclass
class _Direction:
    decoder: StreamDecoder
    last: float = 0.0
    total: int = 0
    buffered: bool = False  # the decoder holds bytes (a partial frame) since the last feed


@dataclass
class Recorder:
    profile: FrameProfile
    idle_flush: float = IDLE_FLUSH
    _dirs: dict[str, _Direction] = field(default_factory=dict)

    def _get(self, direction: str) -> _Direction:
        d = self._dirs.get(direction)
        if d is None:
            d = self._dirs[direction] = _Direction(StreamDecoder(self.profile))
        return d

    def feed(self, direction: str, data: bytes, now: float) -> list[CaptureRecord]:
        d = self._dirs.get(direction) or self._get(direction)
        d.last = now
        d.total += len(data)
        records = d.decoder.feed(data)
        d.buffered = d.decoder.buffered > 0
        return [CaptureRecord(now, direction, r.raw) for r in records]

    def passed(self, direction: str, data: bytes, now: float) -> list[CaptureRecord]:
        """`feed`, then `handle_timer` -- in one step, for bytes passing the tap: a direction
        idle long enough with a partial frame is flushed behind them (`direction` itself, fed
        now, is not idle)."""
        d = self._dirs.get(direction) or self._get(direction)  # `feed`, inline
        d.last = now
        d.total += len(data)
        decoder = d.decoder
        records = decoder.feed(data)
        d.buffered = decoder.buffered > 0
        out = [CaptureRecord(now, direction, r.raw) for r in records] if records else []
        idle_flush = self.idle_flush
        for other in self._dirs.values():
            if other is not d and other.buffered and now >= other.last + idle_flush:
                out += self.handle_timer(now)
                break
        return out

    def handle_timer(self, now: float) -> list[CaptureRecord]:
        """A direction idle for `idle_flush` with a partial frame: that frame, as it stands."""
        out: list[CaptureRecord] = []
        for name, d in self._dirs.items():
            # the sum next_deadline() gives: `now - d.last >= idle_flush` can round the other
            # way at that very deadline and leave it standing at `now`
            if d.buffered and now >= d.last + self.idle_flush:
                out += [CaptureRecord(d.last, name, r.raw) for r in d.decoder.close()]
                d.decoder = StreamDecoder(self.profile, offset=d.total)
                d.buffered = False
        return out

    def flush(self) -> list[CaptureRecord]:
        """Everything still buffered, as it stands (the tap is stopping or reconnecting)."""
        out: list[CaptureRecord] = []
        for name, d in self._dirs.items():
            out += [CaptureRecord(d.last, name, r.raw) for r in d.decoder.close()]
            d.decoder = StreamDecoder(self.profile, offset=d.total)
            d.buffered = False
        return out

    def next_deadline(self) -> float | None:
        best: float | None = None
        for d in self._dirs.values():
            if d.buffered:
                t = d.last + self.idle_flush
                if best is None or t < best:
                    best = t
        return best
