"""The fault injector of one direction of a line, sans-I/O: bytes and `now` in, bytes out later.

A `FaultInjector` sits on one direction of a link. `feed(data, now)` takes what the sender wrote
(and returns nothing: it only queues); `handle_timer(now)` returns what the receiver gets by
`now`; `next_deadline()` says when that changes (a delayed byte, or a frame held for a
frame-aware fault) -- the timer shape of every core (`ktcs_bench.timed`). It never sleeps or reads a clock; its
randomness comes from the `random.Random` it is given, so a seed replays the same errors.

Faults, applied in this order:
    Cut             discard everything (the wire is cut) until `restore()`
    DropBytes(n)    discard the next n bytes
    DropFrame(n)    frame-aware: remove the next n whole frames
    DuplicateFrame  frame-aware: deliver the next n frames twice
    ReorderFrames   frame-aware: deliver the next two frames swapped
    CorruptFrame    frame-aware: XOR one byte of the next frame with a mask
    TruncateFrame   frame-aware: the next frame loses its last n bytes
    BitErrors(rate) flip each delivered bit with probability `rate` (until cleared)
    ByteLoss(rate)  lose each delivered byte with probability `rate` (until cleared)
    Noise(rate)     after each delivered byte, with probability `rate`, a burst of 1..12 random
                    bytes (half of them starting with a false STX) (until cleared)
    Delay(s)        deliver every byte s seconds late (until cleared); byte order is kept
    InsertGarbage   put bytes on the wire now
Frame-aware faults frame the stream with the `StreamDecoder`; while one is armed, bytes are held
until their frame is complete (or the line has been idle for `hold_timeout`). Otherwise bytes pass
through at once. The random faults are Bernoulli processes over the bits/bytes of the stream, so
how the stream is chunked changes nothing.

Each fault has a words form (`command()`: `ber 0.001 ixl>atc`, what a person types to a tap) and a
JSON form (`to_json()` / `fault_from_json`: `{"cmd": "ber", "rate": 0.001, "direction":
"ixl>atc"}`, what a tap's control port takes). `direction` is "a>b" with the link's end names, or
None for both directions; which directions exist is the user's (the tap's) business.
"""

from __future__ import annotations

import dataclasses
import math
import random
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypedDict

from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import UsageError

# A frame-aware fault holds a partial frame at most this long after the last byte came in; a frame
# held for reordering waits at most REORDER_TIMEOUT for the frame to swap it with.
HOLD_TIMEOUT = 0.25
REORDER_TIMEOUT = 5.0
NOISE_LONGEST = 12  # the longest burst of noise, bytes


@dataclass(frozen=True, kw_only=True)
class Fault:
    """A fault for one direction (`a>b`), or both when `direction` is None."""

    direction: str | None = None
    verb: ClassVar[str] = ""

    def command(self) -> str:
        """The words that mean this fault (`ber 0.001 a>b`)."""
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        """The JSON command that means this fault: {"cmd": VERB, its fields, "direction"}."""
        out: dict[str, Any] = {"cmd": self.verb}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "direction":
                if value is not None:
                    out["direction"] = value
            elif isinstance(value, bytes):
                out["hex"] = value.hex()
            else:
                out[f.name] = value
        return out

    def _dir(self) -> str:
        return f" {self.direction}" if self.direction else ""


def _rate(verb: str, rate: float) -> None:
    if not 0.0 <= rate <= 1.0:
        raise UsageError(f"{verb}: the rate must be within 0..1, not {rate}")


def _at_least(verb: str, what: str, n: int, least: int) -> None:
    if n < least:
        raise UsageError(f"{verb}: the {what} must be at least {least}, not {n}")


@dataclass(frozen=True)
class BitErrors(Fault):
    rate: float
    verb: ClassVar[str] = "ber"

    def __post_init__(self) -> None:
        if not 0.0 <= self.rate <= 1.0:
            raise UsageError(f"bit error rate must be within 0..1, not {self.rate}")

    def command(self) -> str:
        return f"ber {self.rate:g}{self._dir()}"


@dataclass(frozen=True)
class ByteLoss(Fault):
    rate: float
    verb: ClassVar[str] = "loss"

    def __post_init__(self) -> None:
        _rate(self.verb, self.rate)

    def command(self) -> str:
        return f"loss {self.rate:g}{self._dir()}"


@dataclass(frozen=True)
class Noise(Fault):
    rate: float
    longest: int = NOISE_LONGEST
    verb: ClassVar[str] = "noise"

    def __post_init__(self) -> None:
        _rate(self.verb, self.rate)
        _at_least(self.verb, "longest burst", self.longest, 1)

    def command(self) -> str:
        longest = "" if self.longest == NOISE_LONGEST else f" {self.longest}"
        return f"noise {self.rate:g}{longest}{self._dir()}"


@dataclass(frozen=True)
class DropFrame(Fault):
    count: int = 1
    verb: ClassVar[str] = "drop-frame"

    def __post_init__(self) -> None:
        _at_least(self.verb, "count", self.count, 1)

    def command(self) -> str:
        return f"drop-frame {self.count}{self._dir()}"


@dataclass(frozen=True)
class DropBytes(Fault):
    count: int
    verb: ClassVar[str] = "drop-bytes"

    def __post_init__(self) -> None:
        _at_least(self.verb, "count", self.count, 0)

    def command(self) -> str:
        return f"drop-bytes {self.count}{self._dir()}"


@dataclass(frozen=True)
class InsertGarbage(Fault):
    data: bytes
    verb: ClassVar[str] = "garbage"

    def __post_init__(self) -> None:
        if not self.data:
            raise UsageError("garbage: give the bytes in hex, e.g. garbage a->b 02 ff 00")

    def command(self) -> str:
        return f"garbage{self._dir()} {self.data.hex(' ')}"


@dataclass(frozen=True)
class DuplicateFrame(Fault):
    count: int = 1
    verb: ClassVar[str] = "duplicate"

    def __post_init__(self) -> None:
        _at_least(self.verb, "count", self.count, 1)

    def command(self) -> str:
        return f"duplicate {self.count}{self._dir()}"


@dataclass(frozen=True)
class ReorderFrames(Fault):
    verb: ClassVar[str] = "reorder"

    def command(self) -> str:
        return f"reorder{self._dir()}"


@dataclass(frozen=True)
class CorruptFrame(Fault):
    """XOR byte `at` of the next frame (negative: from its end) with `mask`."""

    at: int
    mask: int = 0x01
    verb: ClassVar[str] = "corrupt"

    def __post_init__(self) -> None:
        if not 1 <= self.mask <= 0xFF:
            raise UsageError(f"corrupt: the mask must be within 0x01..0xff, not {self.mask}")

    def command(self) -> str:
        return f"corrupt {self.at} 0x{self.mask:02x}{self._dir()}"


@dataclass(frozen=True)
class TruncateFrame(Fault):
    """The next frame loses its last `tail` bytes."""

    tail: int
    verb: ClassVar[str] = "truncate"

    def __post_init__(self) -> None:
        _at_least(self.verb, "number of bytes", self.tail, 1)

    def command(self) -> str:
        return f"truncate {self.tail}{self._dir()}"


@dataclass(frozen=True)
class Delay(Fault):
    seconds: float
    verb: ClassVar[str] = "delay"

    def __post_init__(self) -> None:
        if not 0.0 <= self.seconds <= 3600.0:
            raise UsageError(f"delay must be within 0..3600 s, not {self.seconds}")

    def command(self) -> str:
        return f"delay {self.seconds:g}{self._dir()}"


@dataclass(frozen=True)
class Cut(Fault):
    verb: ClassVar[str] = "cut"

    def command(self) -> str:
        return f"cut{self._dir()}"


_ALL: tuple[type[Fault], ...] = (BitErrors, ByteLoss, Noise, DropFrame, DropBytes, InsertGarbage,
                                 DuplicateFrame, ReorderFrames, CorruptFrame, TruncateFrame, Delay,
                                 Cut)  # fmt: skip
FAULTS: dict[str, type[Fault]] = {cls.verb: cls for cls in _ALL}
_FRAME_FAULTS = (DropFrame, DuplicateFrame, ReorderFrames, CorruptFrame, TruncateFrame)
FrameFault = DropFrame | DuplicateFrame | ReorderFrames | CorruptFrame | TruncateFrame


def fault_from_json(obj: Mapping[str, object]) -> Fault:
    """`{"cmd": "ber", "rate": 0.001, "direction": "a>b"}` -> BitErrors(0.001, direction="a>b").
    Other keys are ignored; a missing or mistyped field is a UsageError naming it."""
    verb = obj.get("cmd")
    cls = FAULTS.get(verb) if isinstance(verb, str) else None
    if cls is None:
        raise UsageError(f"unknown fault {verb!r}; known: {', '.join(FAULTS)}")
    direction = obj.get("direction")
    if direction is not None and not isinstance(direction, str):
        raise UsageError(f'{verb}: direction must be a string like "a>b", not {direction!r}')
    args: dict[str, Any] = {"direction": direction}
    for f in dataclasses.fields(cls):
        if f.name == "direction":
            continue
        key = "hex" if f.type == "bytes" else f.name
        if key not in obj:
            if f.default is dataclasses.MISSING:
                raise UsageError(f"{verb}: {key} is missing")
            continue
        args[f.name] = _value(cls.verb, key, str(f.type), obj[key])
    return cls(**args)


def _value(verb: str, key: str, kind: str, value: object) -> bytes | int | float:
    if kind == "bytes":
        if isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError:
                pass
        raise UsageError(f"{verb}: {key} must be a hex string, not {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UsageError(f"{verb}: {key} must be a number, not {value!r}")
    if kind == "int":
        if value != int(value):
            raise UsageError(f"{verb}: {key} must be a whole number, not {value!r}")
        return int(value)
    if not math.isfinite(value):
        raise UsageError(f"{verb}: {key} must be a finite number, not {value!r}")
    return float(value)


def _geometric(rng: random.Random, p: float) -> int:
    """Failures before the first success of Bernoulli(p) trials."""
    if p >= 1.0:
        return 0
    return int(math.log1p(-rng.random()) / math.log1p(-p))


@dataclass
class FaultStats:
    bytes_in: int = 0
    bytes_out: int = 0
    bits_flipped: int = 0
    bytes_dropped: int = 0
    frames_dropped: int = 0
    frames_duplicated: int = 0
    frames_reordered: int = 0
    frames_corrupted: int = 0
    frames_truncated: int = 0
    garbage_inserted: int = 0


class InjectorState(TypedDict):
    """What a direction's injector does now (`FaultInjector.describe`, a tap's status)."""

    cut: bool
    ber: float
    loss: float
    noise: float
    delay: float
    drop_bytes_pending: int
    frame_faults_pending: list[str]
    holding: bool
    stats: dict[str, int]  # FaultStats' counters by name


@dataclass
class _FrameOp:
    fault: FrameFault
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
        self.loss = 0.0
        self.noise = 0.0
        self.noise_longest = NOISE_LONGEST
        self.delay = 0.0
        self.cut = False
        self._drop_bytes = 0
        self._ops: deque[_FrameOp] = deque()
        self._decoder: StreamDecoder | None = None
        self._last_in = 0.0
        self._held: tuple[float, bytes] | None = None  # a frame waiting to be swapped
        self._out: deque[tuple[float, bytes]] = deque()
        self._last_release = 0.0
        # trials (bits, bytes) left before the next hit of each random fault; -1: draw anew
        self._skip = {"ber": -1, "loss": -1, "noise": -1}
        # one random stream each, so that how the byte stream is chunked changes nothing
        self._rngs = {k: random.Random(self.rng.getrandbits(64)) for k in (*self._skip, "burst")}

    @classmethod
    def seeded(cls, profile: FrameProfile, seed: int) -> FaultInjector:
        return cls(profile, random.Random(seed))

    @property
    def idle(self) -> bool:
        """No fault set and nothing held: bytes pass through unchanged, at once."""
        return not (self.ber or self.loss or self.noise or self.delay or self.cut
                    or self._drop_bytes or self._ops or self._decoder or self._out)  # fmt: skip

    # -- commands ----------------------------------------------------------------------------
    def apply(self, fault: Fault, now: float) -> None:
        if isinstance(fault, BitErrors):
            self.ber = fault.rate
            self._skip["ber"] = -1
        elif isinstance(fault, ByteLoss):
            self.loss = fault.rate
            self._skip["loss"] = -1
        elif isinstance(fault, Noise):
            self.noise = fault.rate
            self.noise_longest = fault.longest
            self._skip["noise"] = -1
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
        elif isinstance(fault, _FRAME_FAULTS):
            count = fault.count if isinstance(fault, DropFrame | DuplicateFrame) else 1
            self._ops.append(_FrameOp(fault, max(1, count)))
            if self._decoder is None:
                self._decoder = StreamDecoder(self.profile)
        else:
            raise UsageError(f"unknown fault {fault!r}")

    def restore(self) -> None:
        """End a cut."""
        self.cut = False

    def clear(self, now: float) -> None:
        """Remove every fault; bytes held for a frame-aware fault are released now."""
        self.ber = self.loss = self.noise = 0.0
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

    def describe(self) -> InjectorState:
        return {
            "cut": self.cut,
            "ber": self.ber,
            "loss": self.loss,
            "noise": self.noise,
            "delay": self.delay,
            "drop_bytes_pending": self._drop_bytes,
            "frame_faults_pending": [f"{op.fault.verb}x{op.left}" for op in self._ops],
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

    def handle_timer(self, now: float) -> bytes:
        """What the receiver gets by `now` (call after every `feed` and at `next_deadline()`)."""
        if self._decoder is not None and self._decoder.buffered:
            if now >= self._last_in + self.hold_timeout:  # the sum next_deadline() gives
                for rec in self._decoder.close():
                    self._schedule(rec.raw, now)
                self._decoder = StreamDecoder(self.profile)
        if self._held is not None and now >= self._held[0] + REORDER_TIMEOUT:
            self._schedule(self._held[1], now)
            self._held = None
            if self._ops and isinstance(self._ops[0].fault, ReorderFrames):
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
        f = op.fault
        if isinstance(f, DropFrame):
            self.stats.frames_dropped += 1
        elif isinstance(f, DuplicateFrame):
            self.stats.frames_duplicated += 1
            self._schedule(raw, now)
            self._schedule(raw, now)
        elif isinstance(f, CorruptFrame):
            self.stats.frames_corrupted += 1
            buf = bytearray(raw)
            if -len(buf) <= f.at < len(buf):
                buf[f.at] ^= f.mask
            self._schedule(bytes(buf), now)
        elif isinstance(f, TruncateFrame):
            self.stats.frames_truncated += 1
            self.stats.bytes_dropped += min(f.tail, len(raw))
            self._schedule(raw[: max(0, len(raw) - f.tail)], now)
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

    def _hits(self, name: str, p: float, trials: int) -> list[int]:
        """The trials (0..trials-1) a Bernoulli(p) process hits, the process running on from
        the last call: geometric gaps, O(hits) not O(trials)."""
        hits = []
        rng = self._rngs[name]
        pos = self._skip[name] if self._skip[name] >= 0 else _geometric(rng, p)
        while pos < trials:
            hits.append(pos)
            pos += 1 + _geometric(rng, p)
        self._skip[name] = pos - trials
        return hits

    def _line(self, data: bytes) -> bytes:
        """The random faults of the line: bit errors, then lost bytes, then noise."""
        if self.ber > 0.0:
            buf = bytearray(data)
            for pos in self._hits("ber", self.ber, 8 * len(buf)):
                buf[pos >> 3] ^= 1 << (pos & 7)
                self.stats.bits_flipped += 1
            data = bytes(buf)
        if self.loss > 0.0:
            lost = set(self._hits("loss", self.loss, len(data)))
            if lost:
                self.stats.bytes_dropped += len(lost)
                data = bytes(b for i, b in enumerate(data) if i not in lost)
        if self.noise > 0.0 and data:
            out = bytearray()
            start = 0
            burst = self._rngs["burst"]
            for pos in self._hits("noise", self.noise, len(data)):
                out += data[start : pos + 1]
                start = pos + 1
                junk = bytearray(burst.randbytes(burst.randint(1, self.noise_longest)))
                if burst.random() < 0.5:
                    junk[0] = self.profile.stx  # a false frame start
                out += junk
                self.stats.garbage_inserted += len(junk)
            if start:
                data = bytes(out + data[start:])
        return data

    def _schedule(self, data: bytes, now: float, raw: bool = False) -> None:
        if not data or self.cut:
            return
        if not raw:
            data = self._line(data)
            if not data:
                return
        at = max(now + self.delay, self._last_release)
        self._last_release = at
        if self._out and self._out[-1][0] == at:
            self._out[-1] = (at, self._out[-1][1] + data)
        else:
            self._out.append((at, data))
