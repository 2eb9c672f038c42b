"""The tap itself, sans-I/O: bytes and `now` in; deliveries, records, events and a deadline out.

`TapCore` sits between the two ends of one link. `receive(direction, data, now)` takes what an end
wrote, `execute(command, now)` a control command (a fault, `restore`, `clear`, `send`),
`handle_timer(now)` runs what is due at `next_deadline()`. Each returns a `TapOutput`:
    deliveries  (direction, bytes) for the receiving end of that direction, in order
    records     the frames that passed (CaptureRecord, time = when the last byte passed)
    events      the subscriber stream, in the order things happened: one {time, direction, hex}
                per record and {time, event, ...} per fault command, `send` and the carrier
                coming and going (`connected`, `disconnected`, ... as the adapter reports them)
A `FaultInjector` per direction (`ktcs_bench.faults`) corrupts the bytes, a `Recorder` frames what
was delivered, the last HISTORY records are kept, and each `Subscription` gets every event (up to
SUBSCRIBER_QUEUE waiting; the excess is counted as missed). Nothing here reads a clock, sleeps or
touches a file descriptor: the adapters (pty.py, tcp.py) and the runner (runner.py) do.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass, field
from typing import Literal, TypedDict

from ktcs_bench.capture.records import CaptureRecord
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError
from ktcs_bench.faults import Cut, FaultInjector
from ktcs_bench.faults.injector import InjectorState
from ktcs_bench.tap.control import Command
from ktcs_bench.tap.recorder import Recorder

HISTORY = 10_000  # records kept for `records()` and `subscribe history`
SUBSCRIBER_QUEUE = 10_000  # events waiting for one slow subscriber before it misses some


class TapHeader(TypedDict, total=False):
    """The answer to `subscribe` (after "ok"), the first line of the stream: the tap's frame
    profile and protocol, its end names, its name and kind."""

    profile: str
    protocol: str
    names: list[str]
    tap: str | None
    kind: str


class TapEvent(TapHeader, total=False):
    """One line of a tap's subscribe stream: the header first (`TapHeader`), then a record
    {time, direction, hex} or an event of the tap's {time, event, ...}."""

    time: float | None
    direction: str  # a record: "a>b"
    hex: str  # ... and its bytes
    event: str  # fault, send, connected, disconnected; the adapter's (`TapCore.note`): refused,
    #             target-failed (TCP), opened, closed (an external serial end)
    command: str  # fault, send: the command's words
    peer: list[str | int]  # connected, refused: the [host, port]
    reason: str  # disconnected: why
    error: str | None  # target-failed, closed: why
    end: str  # opened, closed: the external end
    endpoint: str  # ... and its serial endpoint


class CoreStatus(TypedDict):
    """The link as the core sees it: cut, records kept, subscribers, each direction's faults."""

    cut: bool
    records: int
    subscribers: int
    directions: dict[str, InjectorState]


class CommandAnswer(TypedDict):
    """A command that changes the link, done: `{"ok": true, "command": WORDS}`."""

    ok: Literal[True]
    command: str


def record_event(record: CaptureRecord) -> TapEvent:
    return {"time": record.time, "direction": record.direction, "hex": record.data.hex()}


@dataclass(slots=True)
class TapOutput:
    deliveries: list[tuple[str, bytes]] = field(default_factory=list)
    records: list[CaptureRecord] = field(default_factory=list)
    # what subscribers are sent (a frame's record event only while there are any)
    events: list[TapEvent] = field(default_factory=list)
    link_cut: bool = False  # the whole link was cut: an adapter that carries connections drops them

    def __bool__(self) -> bool:
        return bool(self.deliveries or self.records or self.events or self.link_cut)


class Subscription:
    """One subscriber's share of the event stream, waiting to be taken."""

    def __init__(self, limit: int = SUBSCRIBER_QUEUE) -> None:
        self.limit = limit
        self.missed = 0
        self._queue: deque[TapEvent] = deque()

    def push(self, event: TapEvent) -> None:
        if len(self._queue) < self.limit:
            self._queue.append(event)
        else:
            self.missed += 1

    def take(self) -> list[TapEvent]:
        out = list(self._queue)
        self._queue.clear()
        return out


class TapCore:
    def __init__(
        self,
        names: tuple[str, str],
        profile: FrameProfile,
        *,
        seed: int = 0,
        history: int = HISTORY,
    ) -> None:
        a, b = names
        if a == b or ">" in a + b or a.endswith("-") or b.endswith("-"):
            raise UsageError(f"tap end names must differ and contain no '>': {names}")
        self.names = (a, b)
        self.profile = profile
        self.directions = (f"{a}>{b}", f"{b}>{a}")
        rng = random.Random(seed)
        self.injectors = {
            d: FaultInjector(profile, random.Random(rng.getrandbits(64))) for d in self.directions
        }
        self._both = tuple(self.injectors.values())
        # both injectors idle (no fault set, nothing held): bytes pass straight through. Only
        # this core changes them; it says so after every change (`_pump`, `disconnected`)
        self._clean = True
        self.recorder = Recorder(profile)
        self.cut_all = False  # `cut` with no direction, until `restore` (all) or `clear`
        self.history: deque[CaptureRecord] = deque(maxlen=history)
        self._subscriptions: list[Subscription] = []

    # -- what comes in -------------------------------------------------------------------------
    def passed(self, direction: str, data: bytes, now: float) -> list[CaptureRecord] | None:
        """`receive` for an adapter that carries bytes on a clean link with nobody subscribed
        (a lab's every idle Type I link): when that holds, `data` goes on unchanged to the other
        end and this is what the output's records would be (written to the captures), nothing
        else; None when it does not (ask `receive`)."""
        if not (data and self._clean) or self._subscriptions:
            return None
        stats = self.injectors[direction].stats
        stats.bytes_in += len(data)
        stats.bytes_out += len(data)
        records = self.recorder.passed(direction, data, now)
        if records:
            self.history.extend(records)
        return records

    def receive(self, direction: str, data: bytes, now: float) -> TapOutput:
        """`data` written by the sending end of `direction` ("a>b")."""
        if data and self._clean:
            # no fault set, nothing held either way: the bytes pass at once and unchanged, as
            # the injector would pass them (its counts kept), and nothing else is due
            stats = self.injectors[direction].stats
            stats.bytes_in += len(data)
            stats.bytes_out += len(data)
            out = TapOutput([(direction, data)])
            records = self.recorder.passed(direction, data, now)
            if records:
                self._publish(out, records)
            return out
        self._clean = False
        self.injectors[direction].feed(data, now)
        return self._pump(now, TapOutput())

    def execute(self, cmd: Command, now: float) -> tuple[CommandAnswer, TapOutput]:
        """A command that changes the link: a fault, `restore`, `clear` or `send`. Its answer
        ({"ok": true, "command": WORDS}) and what it caused; UsageError when it cannot be done."""
        out = TapOutput()
        self._clean = False  # until `_pump` has looked
        if cmd.direction is not None and cmd.direction not in self.directions:
            raise UsageError(f"this tap has directions {', '.join(self.directions)}")
        targets = list(self.directions) if cmd.direction is None else [cmd.direction]
        words = cmd.words()
        event = "fault"
        if cmd.fault is not None:
            for d in targets:
                self.injectors[d].apply(cmd.fault, now)
            if isinstance(cmd.fault, Cut) and cmd.direction is None:
                self.cut_all = out.link_cut = True
        elif cmd.verb == "clear":
            for inj in self.injectors.values():
                inj.clear(now)
            self.cut_all = False
        elif cmd.verb == "restore":
            for d in targets:
                self.injectors[d].restore()
            if cmd.direction is None:
                self.cut_all = False
            words = "restore"
        elif cmd.verb == "send":
            assert cmd.direction is not None
            self.injectors[cmd.direction].feed(cmd.data, now)
            event = "send"
        else:
            raise UsageError(f"{cmd.verb}: not a command that changes the link")
        self._emit(out, {"time": now, "event": event, "command": words})
        return {"ok": True, "command": words}, self._pump(now, out)

    def note(self, now: float, said: TapEvent) -> TapOutput:
        """An event of the carrier the adapter saw (`{"event": "refused", "peer": ...}`), into
        the stream at `now`."""
        out = TapOutput()
        self._emit(out, {"time": now, **said})
        return out

    def connected(self, now: float, peer: tuple[str, int]) -> TapOutput:
        """A new connection carries the link: what the recorder holds of the old one is out."""
        out = TapOutput()
        self._publish(out, self.recorder.flush())
        self._emit(out, {"time": now, "event": "connected", "peer": list(peer)})
        return out

    def disconnected(self, now: float, reason: str) -> TapOutput:
        """The connection that carried the link is gone: nothing queued for it (delayed, held
        for a frame fault) reaches the next one."""
        out = TapOutput()
        for inj in self._both:
            inj.discard()
        self._clean = all(inj.idle for inj in self._both)
        self._emit(out, {"time": now, "event": "disconnected", "reason": reason})
        return out

    def handle_timer(self, now: float) -> TapOutput:
        return self._pump(now, TapOutput())

    def next_deadline(self) -> float | None:
        best = self.recorder.next_deadline()
        if self._clean:
            return best
        for inj in self._both:
            t = inj.next_deadline()
            if t is not None and (best is None or t < best):
                best = t
        return best

    def close(self) -> TapOutput:
        """The tap stops: what the recorder still holds, as it stands."""
        out = TapOutput()
        self._publish(out, self.recorder.flush())
        return out

    # -- subscribers -----------------------------------------------------------------------------
    def subscribe(self, history: bool = False, limit: int = SUBSCRIBER_QUEUE) -> Subscription:
        sub = Subscription(limit)
        if history:
            for r in self.history:
                sub.push(record_event(r))
        self._subscriptions.append(sub)
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        if sub in self._subscriptions:
            self._subscriptions.remove(sub)

    # -- looking -----------------------------------------------------------------------------------
    def status(self) -> CoreStatus:
        return {
            "cut": self.cut_all,
            "records": len(self.history),
            "subscribers": len(self._subscriptions),
            "directions": {d: inj.describe() for d, inj in self.injectors.items()},
        }

    # -- internals ---------------------------------------------------------------------------------
    def _pump(self, now: float, out: TapOutput) -> TapOutput:
        for d, inj in self.injectors.items():
            data = inj.handle_timer(now)
            if data:
                out.deliveries.append((d, data))
                self._publish(out, self.recorder.feed(d, data, now))
        self._publish(out, self.recorder.handle_timer(now))
        self._clean = all(inj.idle for inj in self._both)
        return out

    def _publish(self, out: TapOutput, records: list[CaptureRecord]) -> None:
        out.records += records
        self.history.extend(records)
        if self._subscriptions:  # a frame's event is streamed only (a tap's frames go unwatched)
            for r in records:
                self._emit(out, record_event(r))

    def _emit(self, out: TapOutput, event: TapEvent) -> None:
        out.events.append(event)
        for sub in self._subscriptions:
            sub.push(event)
