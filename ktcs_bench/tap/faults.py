"""Fault injection on one direction's byte stream, sans-I/O: bytes and `now` in, bytes out later.

A `FaultInjector` sits on one direction of a link. `feed(data, now)` takes what the sender wrote;
`poll(now)` returns what the receiver gets by `now`; `next_deadline()` says when to poll again
(a delayed byte, or a frame held for a frame-aware fault). It never sleeps or reads a clock; its
randomness comes from the `random.Random` it is given, so a seed replays the same errors.

Faults, applied in this order:
    Cut             discard everything (the wire is cut) until `restore()`
    DropBytes(n)    discard the next n bytes
    DropFrame(n)    frame-aware: remove the next n whole frames
    DuplicateFrame  frame-aware: deliver the next n frames twice
    ReorderFrames   frame-aware: deliver the next two frames swapped
    BitErrors(rate) flip each delivered bit with probability `rate` (until cleared)
    Delay(s)        deliver every byte s seconds late (until cleared); byte order is kept
    InsertGarbage   put bytes on the wire now
Frame-aware faults frame the stream with the `StreamDecoder`; while one is armed, bytes are held
until their frame is complete (or the line has been idle for `hold_timeout`). Otherwise bytes pass
through at once.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import UsageError

# A frame-aware fault holds a partial frame at most this long after the last byte came in; a frame
# held for reordering waits at most REORDER_TIMEOUT for the frame to swap it with.
HOLD_TIMEOUT = 0.25
REORDER_TIMEOUT = 5.0


@dataclass(frozen=True, kw_only=True)
class Fault:
    """A fault for one direction (`a>b`), or both when `direction` is None."""

    direction: str | None = None

    def command(self) -> str:
        """The control-channel command that means this fault."""
        raise NotImplementedError


def _dir(f: Fault) -> str:
    return f" {f.direction}" if f.direction else ""


@dataclass(frozen=True)
class BitErrors(Fault):
    rate: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.rate <= 1.0:
            raise UsageError(f"bit error rate must be within 0..1, not {self.rate}")

    def command(self) -> str:
        return f"ber {self.rate:g}{_dir(self)}"


@dataclass(frozen=True)
class DropFrame(Fault):
    count: int = 1

    def command(self) -> str:
        return f"drop-frame {self.count}{_dir(self)}"


@dataclass(frozen=True)
class DropBytes(Fault):
    count: int

    def command(self) -> str:
        return f"drop-bytes {self.count}{_dir(self)}"


@dataclass(frozen=True)
class InsertGarbage(Fault):
    data: bytes

    def command(self) -> str:
        return f"garbage{_dir(self)} {self.data.hex(' ')}"


@dataclass(frozen=True)
class DuplicateFrame(Fault):
    count: int = 1

    def command(self) -> str:
        return f"duplicate {self.count}{_dir(self)}"


@dataclass(frozen=True)
class ReorderFrames(Fault):
    def command(self) -> str:
        return f"reorder{_dir(self)}"


@dataclass(frozen=True)
class Delay(Fault):
    seconds: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.seconds <= 3600.0:
            raise UsageError(f"delay must be within 0..3600 s, not {self.seconds}")

    def command(self) -> str:
        return f"delay {self.seconds:g}{_dir(self)}"


@dataclass(frozen=True)
class Cut(Fault):
    def command(self) -> str:
        return f"cut{_dir(self)}"


@dataclass
class FaultStats:
    bytes_in: int = 0
    bytes_out: int = 0
    bits_flipped: int = 0
    bytes_dropped: int = 0
    frames_dropped: int = 0
    frames_duplicated: int = 0
    frames_reordered: int = 0
    garbage_inserted: int = 0


@dataclass
class _FrameOp:
    kind: str  # "drop" | "dup" | "reorder"
    left: int


@dataclass
class FaultInjector:
    """The faults of one direction. See the module docstring for the order they apply in."""

    profile: FrameProfile
    rng: random.Random = field(default_factory=lambda: random.Random(0))
    hold_timeout: float = HOLD_TIMEOUT
    stats: FaultStats = field(default_factory=FaultStats)

    def __post_init__(self) -> None:
        self.ber = 0.0
        self.delay = 0.0
        self.cut = False
        self._drop_bytes = 0
        self._ops: deque[_FrameOp] = deque()
        self._decoder: StreamDecoder | None = None
        self._last_in = 0.0
        self._held: tuple[float, bytes] | None = None  # a frame waiting to be swapped
        self._out: deque[tuple[float, bytes]] = deque()
        self._last_release = 0.0
        self._skip = -1  # error-free bits before the next flipped bit; -1: draw anew

    # -- commands ----------------------------------------------------------------------------
    def apply(self, fault: Fault, now: float) -> None:
        if isinstance(fault, BitErrors):
            self.ber = fault.rate
            self._skip = -1
        elif isinstance(fault, Delay):
            self.delay = fault.seconds
        elif isinstance(fault, Cut):
            self.cut = True
            self._out.clear()
            self._last_release = 0.0
        elif isinstance(fault, DropBytes):
            self._drop_bytes += max(0, fault.count)
        elif isinstance(fault, InsertGarbage):
            self.stats.garbage_inserted += len(fault.data)
            self._schedule(fault.data, now, raw=True)
        elif isinstance(fault, DropFrame | DuplicateFrame | ReorderFrames):
            kind = {DropFrame: "drop", DuplicateFrame: "dup", ReorderFrames: "reorder"}[type(fault)]
            count = 1 if isinstance(fault, ReorderFrames) else max(1, fault.count)
            self._ops.append(_FrameOp(kind, count))
            if self._decoder is None:
                self._decoder = StreamDecoder(self.profile)
        else:
            raise UsageError(f"unknown fault {fault!r}")

    def restore(self) -> None:
        """End a cut."""
        self.cut = False

    def clear(self, now: float) -> None:
        """Remove every fault; bytes held for a frame-aware fault are released now."""
        self.ber = 0.0
        self.delay = 0.0
        self.cut = False
        self._drop_bytes = 0
        self._ops.clear()
        self._release_frames(now)

    def discard(self) -> None:
        """The connection this direction carried is gone: what is still queued for it (delayed,
        held for a frame fault, half a frame) is dropped, never delivered on the next one."""
        lost = sum(len(b) for _, b in self._out) + (len(self._held[1]) if self._held else 0)
        if self._decoder is not None:
            lost += self._decoder.buffered
            self._decoder = StreamDecoder(self.profile)
        self.stats.bytes_dropped += lost
        self._out.clear()
        self._held = None
        self._last_release = 0.0  # nothing queued is left to keep the next bytes behind

    def describe(self) -> dict[str, Any]:
        return {
            "cut": self.cut,
            "ber": self.ber,
            "delay": self.delay,
            "drop_bytes_pending": self._drop_bytes,
            "frame_faults_pending": [f"{op.kind}x{op.left}" for op in self._ops],
            "holding": self._held is not None or bool(self._decoder and self._decoder.buffered),
            "stats": vars(self.stats).copy(),
        }

    # -- data path ---------------------------------------------------------------------------
    def feed(self, data: bytes, now: float) -> None:
        self.stats.bytes_in += len(data)
        if self.cut:
            self.stats.bytes_dropped += len(data)
            return
        if self._drop_bytes:
            n = min(self._drop_bytes, len(data))
            self._drop_bytes -= n
            self.stats.bytes_dropped += n
            data = data[n:]
        if not data:
            return
        if self._decoder is None:
            self._schedule(data, now)
            return
        self._last_in = now
        for rec in self._decoder.feed(data):
            self._frame_stage(rec.raw, isinstance(rec, Frame) and rec.error is None, now)
        self._maybe_stop_framing(now)

    def poll(self, now: float) -> bytes:
        """What the receiver gets by `now`."""
        if self._decoder is not None and self._decoder.buffered:
            if now - self._last_in >= self.hold_timeout:
                for rec in self._decoder.close():
                    self._schedule(rec.raw, now)
                self._decoder = StreamDecoder(self.profile)
        if self._held is not None and now - self._held[0] >= REORDER_TIMEOUT:
            self._schedule(self._held[1], now)
            self._held = None
            if self._ops and self._ops[0].kind == "reorder":
                self._ops.popleft()
            self._maybe_stop_framing(now)
        out = bytearray()
        while self._out and self._out[0][0] <= now:
            out += self._out.popleft()[1]
        self.stats.bytes_out += len(out)
        return bytes(out)

    def next_deadline(self) -> float | None:
        times = []
        if self._out:
            times.append(self._out[0][0])
        if self._decoder is not None and self._decoder.buffered:
            times.append(self._last_in + self.hold_timeout)
        if self._held is not None:
            times.append(self._held[0] + REORDER_TIMEOUT)
        return min(times) if times else None

    # -- internals ---------------------------------------------------------------------------
    def _frame_stage(self, raw: bytes, is_frame: bool, now: float) -> None:
        if not is_frame or not self._ops:
            self._schedule(raw, now)
            return
        op = self._ops[0]
        if op.kind == "drop":
            self.stats.frames_dropped += 1
        elif op.kind == "dup":
            self.stats.frames_duplicated += 1
            self._schedule(raw, now)
            self._schedule(raw, now)
        elif self._held is None:
            self._held = (now, raw)
            return
        else:
            self.stats.frames_reordered += 1
            self._schedule(raw, now)
            self._schedule(self._held[1], now)
            self._held = None
        op.left -= 1
        if op.left <= 0:
            self._ops.popleft()

    def _maybe_stop_framing(self, now: float) -> None:
        if not self._ops and self._held is None and self._decoder is not None:
            self._release_frames(now)

    def _release_frames(self, now: float) -> None:
        if self._held is not None:
            self._schedule(self._held[1], now)
            self._held = None
        if self._decoder is not None:
            for rec in self._decoder.close():
                self._schedule(rec.raw, now)
            self._decoder = None

    def _flip(self, data: bytes) -> bytes:
        p = self.ber
        if p <= 0.0 or not data:
            return data
        nbits = 8 * len(data)
        buf = bytearray(data)
        pos = self._skip if self._skip >= 0 else self._draw(p)
        while pos < nbits:
            buf[pos >> 3] ^= 1 << (pos & 7)
            self.stats.bits_flipped += 1
            pos += 1 + self._draw(p)
        self._skip = pos - nbits
        return bytes(buf)

    def _draw(self, p: float) -> int:
        """Error-free bits before the next error: geometric with success probability p."""
        if p >= 1.0:
            return 0
        u = self.rng.random()
        return int(math.log1p(-u) / math.log1p(-p))

    def _schedule(self, data: bytes, now: float, raw: bool = False) -> None:
        if not data or self.cut:
            return
        if not raw:
            data = self._flip(data)
        at = max(now + self.delay, self._last_release)
        self._last_release = at
        if self._out and self._out[-1][0] == at:
            self._out[-1] = (at, self._out[-1][1] + data)
        else:
            self._out.append((at, data))
