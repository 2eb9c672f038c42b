"""Two `Type1Link`s joined by an in-memory wire on the virtual clock, stepped deterministically.

Owns: `VirtualWire` (one direction of a line: line-rate delays, the line's `FaultInjector`, a
record of what was sent and what arrived; itself a `Timed` core whose output is the bytes that
arrive) and `VirtualBench` (two links and two wires on one `ktcs_bench.timed.virtual.VirtualClock`,
the one virtual-clock driver). The same link objects run here as on ptys; nothing here sleeps or
reads a clock, so a test runs seconds of line time in milliseconds. A bench's `clock` takes more
cores (`bench.clock.add(core, sink)`): a whole station can run beside its links.

Bytes leave a link through `data_to_send(now)`, pass the wire's fault injector
(`ktcs_bench.faults`: cut, bit errors, lost bytes, noise, frame faults, delay -- the same injector
a tap puts between real ends) and arrive at the peer in pieces of `piece` bytes, each when its
last byte would have finished on the wire (bytes × bits_per_byte / line_rate), so a frame arrives
progressively and ΔR can expire in its middle. `wire.apply(Cut(), now)`, `wire.restore()`,
`wire.apply(BitErrors(1e-3), now)`: a fault is set on a wire as on a tap.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.faults import Fault, FaultInjector
from ktcs_bench.timed.virtual import VirtualClock
from ktcs_bench.type1 import LinkEvent, Message, Type1Link

PIECE = 8
"""Bytes of a piece: a frame arrives in pieces of this many bytes, each when its last has."""

Flight = deque[tuple[float, bytes]]
"""The pieces on a line, in order: (when its last byte arrives, the piece)."""


def put_in_pieces(
    flight: Flight, data: bytes, start: float, byte_time: float, piece: int = PIECE
) -> float:
    """Put `data` on a line that is free from `start`, one piece after another at `byte_time` a
    byte; when the line is free again."""
    n = len(data)
    for i in range(0, n, piece):
        chunk = data[i : i + piece]
        flight.append((start + (i + len(chunk)) * byte_time, chunk))
    return start + n * byte_time


def take_arrived(flight: Flight, now: float) -> bytes:
    """The pieces that have arrived by `now`, joined (mostly the only one)."""
    if not flight or flight[0][0] > now:
        return b""
    out = flight.popleft()[1]
    if flight and flight[0][0] <= now:
        more = bytearray(out)
        while flight and flight[0][0] <= now:
            more += flight.popleft()[1]
        out = bytes(more)
    return out


@dataclass
class VirtualWire:
    """One direction of the line. `faults` is its injector (a clean wire until a fault is set)."""

    byte_time: float
    profile: FrameProfile
    piece: int = PIECE
    faults: FaultInjector | None = None
    seed: int = 0
    record: bool = True  # keep `sent` and `arrived` (a long-running wire does not)
    sent: list[tuple[float, bytes]] = field(default_factory=list)  # as the sender handed them
    arrived: list[tuple[float, bytes]] = field(default_factory=list)  # as the receiver got them
    _free_at: float = 0.0
    _flight: Flight = field(default_factory=deque)

    @property
    def injector(self) -> FaultInjector:
        """The wire's fault injector, made (seeded with `seed`) when first wanted."""
        if self.faults is None:
            self.faults = FaultInjector.seeded(self.profile, self.seed)
        return self.faults

    def apply(self, fault: Fault, now: float) -> None:
        self.injector.apply(fault, now)
        self._release(now)

    def restore(self) -> None:
        """End a cut."""
        self.injector.restore()

    def put(self, data: bytes, now: float) -> None:
        """What the sender writes at `now`: through the faults, onto the line."""
        if self.record:
            self.sent.append((now, data))
        if self.faults is None:
            self._line(data, now)
            return
        self.faults.feed(data, now)
        self._release(now)

    def put_raw(self, data: bytes, now: float) -> None:
        """Bytes on the line now, as if the sender had written them, past the faults (a cut
        wire carries nothing)."""
        self.sent.append((now, data))
        if self.faults is None or not self.faults.cut:
            self._line(data, now)

    def next_deadline(self) -> float | None:
        """When bytes next arrive (or the fault injector releases some)."""
        flight = self._flight
        first = flight[0][0] if flight else None
        if self.faults is not None and (held := self.faults.next_deadline()) is not None:
            return held if first is None or held < first else first
        return first

    def handle_timer(self, now: float) -> bytes:
        """The bytes that have arrived at the receiver by `now`."""
        if self.faults is not None:
            self._release(now)
        out = take_arrived(self._flight, now)
        if not out:
            return b""
        if self.record:
            self.arrived.append((now, out))
        return out

    def sent_bytes(self) -> bytes:
        return b"".join(d for _, d in self.sent)

    def _release(self, now: float) -> None:
        """What the fault injector lets through by `now` goes onto the line."""
        if self.faults is not None:
            data = self.faults.handle_timer(now)
            if data:
                self._line(data, now)

    def _line(self, data: bytes, now: float) -> None:
        # its pieces are handed on as they are (bytes(): a no-op for bytes)
        self._free_at = put_in_pieces(self._flight, bytes(data), max(now, self._free_at),
                                      self.byte_time, self.piece)  # fmt: skip


class VirtualBench:
    """Links `a` and `b` over two `VirtualWire`s on a virtual clock -- its own, or `clock`, shared
    with other benches and cores; `events` collects (time, link name, event). Bytes a link hands
    out after any call go onto its wire at once."""

    def __init__(
        self,
        a: Type1Link,
        b: Type1Link,
        *,
        piece: int = PIECE,
        faults_ab: FaultInjector | None = None,
        faults_ba: FaultInjector | None = None,
        start: float = 0.0,
        clock: VirtualClock | None = None,
    ) -> None:
        self.a, self.b = a, b
        self.ab = VirtualWire(a.timers.byte_time, a.profile, piece, faults_ab, seed=1)
        self.ba = VirtualWire(b.timers.byte_time, b.profile, piece, faults_ba, seed=2)
        self.clock = clock if clock is not None else VirtualClock(start)
        self.events: list[tuple[float, str, LinkEvent]] = []
        self._out = {id(a): self.ab, id(b): self.ba}
        # the wires first: an instant's arrivals reach the links before their timers run
        self.clock.add(self.ab, lambda now, data: self._deliver(b, data, now))
        self.clock.add(self.ba, lambda now, data: self._deliver(a, data, now))
        for link in (a, b):
            self.clock.add(link, self._sink(link))
        for link in (a, b):  # the line opens: both ends start their clocks
            self._after(link, link.handle_timer(self.now), self.now)

    @property
    def now(self) -> float:
        return self.clock.now

    # -- driving -------------------------------------------------------------------------------
    def send(self, link: Type1Link, message: Message) -> None:
        link.send(message, self.now)
        self._after(link, [], self.now)

    def inject(self, wire: VirtualWire, data: bytes) -> None:
        """Put raw bytes on a wire now, as if its sender had written them (faults not applied)."""
        wire.put_raw(data, self.now)

    def fault(self, wire: VirtualWire, fault: Fault) -> None:
        """Set a fault on a wire now (`bench.fault(bench.ab, Cut())`)."""
        wire.apply(fault, self.now)

    def run_until(self, t: float, stop: Callable[[], bool] | None = None) -> None:
        """Step until virtual time `t` (or until `stop()` is true after a step)."""
        self.clock.run_until(t, stop)

    def run_for(self, dt: float, stop: Callable[[], bool] | None = None) -> None:
        self.clock.run_for(dt, stop)

    # -- looking -------------------------------------------------------------------------------
    def of(self, link: Type1Link, *kinds: type) -> list[LinkEvent]:
        """Events of one link, optionally only of the given classes."""
        return [
            e for _, n, e in self.events if n == link.name and (not kinds or isinstance(e, kinds))
        ]

    # -- internals -----------------------------------------------------------------------------
    def _sink(self, link: Type1Link) -> Callable[[float, list[LinkEvent]], None]:
        return lambda now, events: self._after(link, events, now)

    def _deliver(self, link: Type1Link, data: bytes, now: float) -> None:
        if data:
            self._after(link, link.receive_data(data, now), now)

    def _after(self, link: Type1Link, events: list[LinkEvent], now: float) -> None:
        self.events.extend((now, link.name, e) for e in events)
        data = link.data_to_send(now)
        if data:
            self._out[id(link)].put(data, now)
