"""Virtual-clock driver: two `Type1Link`s joined by an in-memory wire, stepped deterministically.

Owns: `VirtualWire` (one direction of a line: line-rate delays, the line's `FaultInjector`, a
record of what was sent and what arrived) and `VirtualBench` (two links, two wires and a virtual
clock that jumps from one due time to the next). The same link objects run here as on ptys;
nothing here sleeps or reads a clock, so a test runs seconds of line time in milliseconds.

Bytes leave a link through `data_to_send(now)`, pass the wire's fault injector
(`ktcs_bench.faults`: cut, bit errors, lost bytes, noise, frame faults, delay -- the same injector
a tap puts between real ends) and arrive at the peer in pieces of `piece` bytes, each when its
last byte would have finished on the wire (bytes × bits_per_byte / line_rate), so a frame arrives
progressively and ΔR can expire in its middle. `wire.apply(Cut(), now)`, `wire.restore()`,
`wire.apply(BitErrors(1e-3), now)`: a fault is set on a wire as on a tap.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.faults import Fault, FaultInjector
from ktcs_bench.type1 import Event, Message, Type1Link

# Guard against a link whose deadline never moves (a bug): this many timer calls at one instant.
MAX_CALLS_PER_INSTANT = 10_000


@dataclass
class VirtualWire:
    """One direction of the line. `faults` is its injector (a clean wire until a fault is set)."""

    byte_time: float
    profile: FrameProfile
    piece: int = 8
    faults: FaultInjector | None = None
    seed: int = 0
    sent: list[tuple[float, bytes]] = field(default_factory=list)  # as the sender handed them
    arrived: list[tuple[float, bytes]] = field(default_factory=list)  # as the receiver got them
    _free_at: float = 0.0
    _flight: deque[tuple[float, bytes]] = field(default_factory=deque)

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

    def next_time(self) -> float | None:
        times = [self._flight[0][0]] if self._flight else []
        if self.faults is not None and (held := self.faults.next_deadline()) is not None:
            times.append(held)
        return min(times) if times else None

    def take(self, now: float) -> bytes:
        self._release(now)
        out = bytearray()
        while self._flight and self._flight[0][0] <= now:
            out += self._flight.popleft()[1]
        if out:
            self.arrived.append((now, bytes(out)))
        return bytes(out)

    def sent_bytes(self) -> bytes:
        return b"".join(d for _, d in self.sent)

    def _release(self, now: float) -> None:
        """What the fault injector lets through by `now` goes onto the line."""
        if self.faults is not None:
            data = self.faults.poll(now)
            if data:
                self._line(data, now)

    def _line(self, data: bytes, now: float) -> None:
        start = max(now, self._free_at)
        bt = self.byte_time
        for i in range(0, len(data), self.piece):
            chunk = data[i : i + self.piece]
            self._flight.append((start + (i + len(chunk)) * bt, chunk))
        self._free_at = start + len(data) * bt


class VirtualBench:
    """Links `a` and `b` over two `VirtualWire`s; `events` collects (time, link name, event)."""

    def __init__(
        self,
        a: Type1Link,
        b: Type1Link,
        *,
        piece: int = 8,
        faults_ab: FaultInjector | None = None,
        faults_ba: FaultInjector | None = None,
        start: float = 0.0,
    ) -> None:
        self.a, self.b = a, b
        self.ab = VirtualWire(a.timers.byte_time, a.profile, piece, faults_ab, seed=1)
        self.ba = VirtualWire(b.timers.byte_time, b.profile, piece, faults_ba, seed=2)
        self.now = start
        self.events: list[tuple[float, str, Event]] = []
        self._pairs = ((a, self.ab, self.ba), (b, self.ba, self.ab))  # (link, out wire, in wire)
        for link, _, _ in self._pairs:
            self._note(link, link.handle_timer(self.now))
        self._flush()

    # -- driving -------------------------------------------------------------------------------
    def send(self, link: Type1Link, message: Message) -> None:
        link.send(message, self.now)
        self._flush()

    def inject(self, wire: VirtualWire, data: bytes) -> None:
        """Put raw bytes on a wire now, as if its sender had written them (faults not applied)."""
        wire.put_raw(data, self.now)

    def fault(self, wire: VirtualWire, fault: Fault) -> None:
        """Set a fault on a wire now (`bench.fault(bench.ab, Cut())`)."""
        wire.apply(fault, self.now)

    def next_time(self) -> float | None:
        times = [t for t in self._times() if t is not None]
        return min(times) if times else None

    def step(self) -> bool:
        """Advance to the next due time and run everything due then; False if nothing is due."""
        t = self.next_time()
        if t is None:
            return False
        self.now = max(self.now, t)
        self._run_instant()
        return True

    def run_until(self, t: float, stop: Callable[[], bool] | None = None) -> None:
        """Step until virtual time `t` (or until `stop()` is true after a step)."""
        while True:
            nt = self.next_time()
            if nt is None or nt > t:
                self.now = max(self.now, t)
                return
            self.step()
            if stop is not None and stop():
                return

    def run_for(self, dt: float, stop: Callable[[], bool] | None = None) -> None:
        self.run_until(self.now + dt, stop)

    # -- looking -------------------------------------------------------------------------------
    def of(self, link: Type1Link, *kinds: type) -> list[Event]:
        """Events of one link, optionally only of the given classes."""
        return [
            e for _, n, e in self.events if n == link.name and (not kinds or isinstance(e, kinds))
        ]

    # -- internals -----------------------------------------------------------------------------
    def _times(self) -> Iterable[float | None]:
        yield self.ab.next_time()
        yield self.ba.next_time()
        yield self.a.next_deadline()
        yield self.b.next_deadline()

    def _run_instant(self) -> None:
        now = self.now
        for link, _, inbound in self._pairs:
            data = inbound.take(now)
            if data:
                self._note(link, link.receive_data(data, now))
        for _ in range(MAX_CALLS_PER_INSTANT):
            due = [
                lk for lk, _, _ in self._pairs if (d := lk.next_deadline()) is not None and d <= now
            ]
            if not due:
                break
            for link in due:
                self._note(link, link.handle_timer(now))
            self._flush()
        else:  # pragma: no cover - a link bug, not a condition of the line
            raise RuntimeError("a link's deadline does not advance")
        self._flush()

    def _flush(self) -> None:
        for link, out, _ in self._pairs:
            data = link.data_to_send(self.now)
            if data:
                out.put(data, self.now)

    def _note(self, link: Type1Link, events: list[Event]) -> None:
        self.events.extend((self.now, link.name, e) for e in events)
