"""The Type I ARQ state machine (SPEC §3.4 ①②③): stop-and-wait per direction, no framing, no I/O.

Owns: which SEQ a message gets, when a frame is (re)sent, when the sender gives up, and whether an
incoming SEQ is new, a duplicate or a gap. Knows nothing of bytes on the wire or of clocks: the link
(`type1.link`) tells it the times.

Sender: a queue, and at most one outstanding frame. A queue entry is a `Message`, or an `Owed`
answer whose DATA is made only when it becomes outstanding (from the state of that moment). Each transmission is counted when its bytes
are handed to the wire; its ACK deadline runs from the end of its bytes on the wire. A NAK or an
ACK timeout asks for a retransmission with the same SEQ, until `max_transmissions` sends have
failed: then the sender gives up (communication error) and moves on to the next SEQ.

Receiver: remembers the last accepted SEQ. The same SEQ again is a duplicate (ACK it, do not
deliver); any other SEQ is accepted, and a gap is noted when it is not the next one.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ktcs_bench.type1.events import Message


class ReceiveVerdict(enum.Enum):
    RETRANSMIT = "retransmit"
    GIVE_UP = "give up"
    IGNORE = "ignore"


@dataclass(frozen=True, slots=True)
class Owed:
    """An answer the peer asked for and we acknowledged (an ALL_INFO for its REQUEST_ALL of
    `start`, `count`): queued as a promise, made into a message when it is first sent."""

    op: int
    start: int
    count: int


Queued = Message | Owed


@dataclass(slots=True)
class Outstanding:
    """The one data frame awaiting its ACK."""

    seq: int
    message: Message
    frame: bytes
    owed: Owed | None = None  # the promise this frame keeps, if it is one
    transmissions: int = 0  # sends handed to the wire so far
    due: bool = True  # bytes waiting to be handed to the wire
    ack_deadline: float | None = None


class Sender:
    def __init__(self, seq_modulo: int, max_transmissions: int, first_seq: int = 0) -> None:
        self.seq_modulo = seq_modulo
        self.max_transmissions = max_transmissions
        self.next_seq = first_seq % seq_modulo
        self.queue: deque[Queued] = deque()
        self.outstanding: Outstanding | None = None

    @property
    def idle(self) -> bool:
        return self.outstanding is None and not self.queue

    def push(self, message: Queued, front: bool = False) -> None:
        if front:
            self.queue.appendleft(message)
        else:
            self.queue.append(message)

    def holds(self, op: int) -> bool:
        """A message with this opcode is queued or outstanding."""
        out = self.outstanding
        return (out is not None and out.message.op == op) or any(m.op == op for m in self.queue)

    def promote(
        self, encode: Callable[[int, Message], bytes], make: Callable[[Owed], Message]
    ) -> Outstanding | None:
        """Make the queue head outstanding (assigning the next SEQ) if nothing is; an `Owed`
        head becomes `make(owed)` now."""
        if self.outstanding is None and self.queue:
            head = self.queue.popleft()
            owed = head if isinstance(head, Owed) else None
            message = make(head) if isinstance(head, Owed) else head
            seq = self.next_seq
            self.next_seq = (seq + 1) % self.seq_modulo
            self.outstanding = Outstanding(seq, message, encode(seq, message), owed)
        return self.outstanding

    def transmitted(self, wire_end: float, ack_timeout: float) -> Outstanding:
        """The outstanding frame's bytes went to the wire, finishing at `wire_end`."""
        out = self.outstanding
        assert out is not None and out.due
        out.due = False
        out.transmissions += 1
        out.ack_deadline = wire_end + ack_timeout
        return out

    def ack(self, seq: int) -> Outstanding | None:
        """An ACK with `seq`: the outstanding frame if it is the one acknowledged."""
        out = self.outstanding
        if out is None or out.seq != seq or out.transmissions == 0:
            return None
        self.outstanding = None
        return out

    def nak(self) -> ReceiveVerdict:
        """A NAK: retransmit the outstanding frame (unless a send of it is already pending)."""
        out = self.outstanding
        if out is None or out.due or out.transmissions == 0:
            return ReceiveVerdict.IGNORE
        return self._failed(out)

    def timeout(self, now: float) -> ReceiveVerdict:
        out = self.outstanding
        if out is None or out.due or out.ack_deadline is None or now < out.ack_deadline:
            return ReceiveVerdict.IGNORE
        return self._failed(out)

    def _failed(self, out: Outstanding) -> ReceiveVerdict:
        if out.transmissions >= self.max_transmissions:
            return ReceiveVerdict.GIVE_UP
        out.due = True
        out.ack_deadline = None
        return ReceiveVerdict.RETRANSMIT

    def give_up(self) -> tuple[Outstanding, tuple[Queued, ...]]:
        """Drop the outstanding frame and everything queued behind it."""
        out = self.outstanding
        assert out is not None
        self.outstanding = None
        return out, self.discard()

    def discard(self) -> tuple[Queued, ...]:
        dropped = tuple(self.queue)
        self.queue.clear()
        return dropped

    def deadline(self) -> float | None:
        out = self.outstanding
        return None if out is None or out.due else out.ack_deadline


@dataclass(frozen=True, slots=True)
class Acceptance:
    duplicate: bool
    gap_expected: int | None  # the SEQ we expected when this one skipped ahead


_NEW = Acceptance(False, None)
_DUPLICATE = Acceptance(True, None)


class Receiver:
    def __init__(self, seq_modulo: int) -> None:
        self.seq_modulo = seq_modulo
        self.last_seq: int | None = None
        self.last_time: float = 0.0

    def accept(self, seq: int, now: float) -> Acceptance:
        last = self.last_seq
        if last is not None and seq == last:
            return _DUPLICATE
        expected = None if last is None else (last + 1) % self.seq_modulo
        self.last_seq = seq
        self.last_time = now
        if expected is None or expected == seq:
            return _NEW
        return Acceptance(False, expected)

    def forget(self) -> None:
        """The peer may have restarted: the next SEQ is new whatever its value."""
        self.last_seq = None
