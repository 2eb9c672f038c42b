"""`Type1Link`: one end of a Type I link as a sans-I/O object (the h11/aioquic shape).

Owns: framing in and out (through `codec`), the ARQ rules of SPEC §3.4 (through `type1.arq`), the
timers (ΔR, ACK timeout, link test, link down) and the link state (up/down, REQUEST_ALL on
recovery). Must not touch: sockets, ptys, clocks, sleeping. Every call takes `now` (seconds, any
monotonic origin) and the caller honours `next_deadline()`.

How a driver uses it (every driver in `ktcs_bench.transport` does exactly this)::

    link = Type1Link("ktcs-type1", LinkConfig(), "ixl18-atc18", state_provider=my_statuses)
    link.handle_timer(now)                  # once when the line opens: starts the clock, probes
    wire.write(link.data_to_send(now))
    ...on bytes:      events = link.receive_data(data, now)
    ...on deadline:   events = link.handle_timer(now)
    ...application:   link.send(link.message("CHANGE", items=[[3, 1]]), now)
    ...after each of those: wire.write(link.data_to_send(now)); re-arm at link.next_deadline()

Bytes go out only through `data_to_send(now)`, which returns everything due (ACK/NAK first, then
at most one data frame) and notes when those bytes finish on the wire at the configured line rate:
the ACK timeout of a data frame runs from that moment.

State rebuild (SPEC §3.4): when the link comes up (the first valid frame after being down) it
queues REQUEST_ALL (start 0, count all) at the head of its queue. A REQUEST_ALL received is
delivered as `MessageReceived` and, when the link was given a `state_provider(start, count)`
returning status bytes, the ALL_INFO that answers it is owed: it is queued as a promise, and
`state_provider` is asked for the statuses only when that frame goes out, so it carries the state
of that moment, not of the request. Without a provider the application answers with
`link.send(link.message("ALL_INFO", statuses=...), now)`. A peer that recovered from an outage we
did not see (its REQUEST_ALL arrives and we have not asked one within `link_down_after`), or a SEQ
gap (the peer gave up on frames), makes this side ask REQUEST_ALL too, so both views are rebuilt.

Communication error (4 transmissions without ACK) drops that message and the ones queued behind it
(reported in the event) and puts the link down; the application goes fail-safe until `LinkUp`.
An owed ALL_INFO is never dropped: we ACKed the request, so the peer waits for its answer. It is
held while the link is down and queued again, after our own REQUEST_ALL, when the link comes up,
made from the state of the moment it is sent.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ktcs_bench.codec import Frame, FrameCodec, FrameProfile, Garbage, StreamDecoder, get_profile
from ktcs_bench.codec.opcodes import Opcode, PayloadError
from ktcs_bench.errors import UsageError
from ktcs_bench.type1.arq import Owed, Queued, Receiver, ReceiveVerdict, Sender
from ktcs_bench.type1.config import LinkConfig, LinkTimers
from ktcs_bench.type1.events import (
    AckReceived,
    AckSent,
    CommunicationError,
    DuplicateReceived,
    GarbageReceived,
    LinkDown,
    LinkEvent,
    LinkUp,
    Message,
    MessageReceived,
    NakReceived,
    NakSent,
    Retransmission,
    SequenceGap,
)

StateProvider = Callable[[int, int], bytes | Sequence[int]]

# The NAK reasons by their names in the profile's `nak_reasons`; the numbers are the profile's.
NAK_CRC = "crc error"
NAK_FRAME_TIMEOUT = "frame timeout"
NAK_FORMAT = "length/format error"
_NAK_FOR_ERROR = {"crc": NAK_CRC, "truncated": NAK_FRAME_TIMEOUT, "etx": NAK_FORMAT}


class Type1Link:
    """One end of a Type I link. See the module docstring for the driving contract."""

    def __init__(
        self,
        profile: FrameProfile | str = "ktcs-type1",
        config: LinkConfig | None = None,
        name: str = "type1",
        *,
        state_provider: StateProvider | None = None,
        first_seq: int = 0,
    ) -> None:
        self.profile = get_profile(profile) if isinstance(profile, str) else profile
        self.config = config if config is not None else LinkConfig()
        self.timers: LinkTimers = self.config.resolve(self.profile)
        self.name = name
        self.state_provider = state_provider
        self._codec = FrameCodec(self.profile)
        self._decoder = StreamDecoder(self.profile)
        self._op = {
            n: self._opcode(n) for n in ("REQUEST_ALL", "ALL_INFO", "LINK_TEST", "ACK", "NAK")
        }
        self._ack_op = self._op["ACK"].op
        # the LINK_TEST an idle link sends every period (a message is immutable: one will do)
        self._link_test = Message(self._op["LINK_TEST"].op, b"", "LINK_TEST")
        self._nak_op = self._op["NAK"].op
        self._nak_reason = {
            meaning: self.profile.nak_reason(meaning)
            for meaning in (NAK_CRC, NAK_FRAME_TIMEOUT, NAK_FORMAT)
        }
        seq_modulo = self._codec.seq_modulo
        self._sender = Sender(seq_modulo, self.timers.max_transmissions, first_seq)
        self._receiver = Receiver(seq_modulo)
        self._control: list[bytes] = []  # ACK/NAK frames waiting for data_to_send
        self.up = False
        self._started = False
        self._silenced = False  # went down by silence: the peer may have restarted
        self._tx_free_at = 0.0  # when our bytes handed out so far finish on the wire
        self._last_rx = 0.0  # last valid frame received
        self._rx_pending_since: float | None = None  # ΔR runs from here
        self._last_request_all: float | None = None
        self._last_seq_seen = 0
        self._held: list[Owed] = []  # answers owed to the peer, held while the link is down

    # -- application side ----------------------------------------------------------------------
    def message(self, op_name: str, **values: object) -> Message:
        """Build a message by opcode name: `link.message("CHANGE", items=[[3, 1]])`."""
        opcode = self._opcode(op_name.upper())
        return Message(opcode.op, opcode.build(values), opcode.name)

    def send(self, message: Message, now: float) -> None:
        """Queue an application message; it goes out, in order, one unacknowledged at a time."""
        self._start(now)
        if message.op in (self._ack_op, self._nak_op):
            raise UsageError("ACK and NAK belong to the link; they are not application messages")
        if len(message.data) > self.profile.max_data:
            raise UsageError(f"{len(message.data)} DATA bytes exceed {self.profile.max_data}")
        if message.op == self._op["REQUEST_ALL"].op:
            self._last_request_all = now
        self._sender.push(message)

    @property
    def queued(self) -> int:
        """Messages not yet acknowledged (outstanding one included)."""
        s = self._sender
        return len(s.queue) + (s.outstanding is not None)

    # -- wire side -----------------------------------------------------------------------------
    def receive_data(self, data: bytes, now: float) -> list[LinkEvent]:
        if not self._started:
            self._start(now)
        events: list[LinkEvent] = []
        decoder = self._decoder
        records = decoder.feed(data)
        if records:
            self._records(records, now, events)
        if not decoder.pending:
            self._rx_pending_since = None
        elif self._rx_pending_since is None or records:
            self._rx_pending_since = now  # a new frame has begun
        return events

    def data_to_send(self, now: float) -> bytes:
        """Everything due on the wire now: ACK/NAK frames first, then at most one data frame."""
        if not self._started:
            self._start(now)
        sender = self._sender
        out = sender.outstanding
        if out is None and sender.queue:
            out = sender.promote(self._encode, self._make)
        frame = out.frame if out is not None and out.due else None
        parts = self._control
        if not parts and frame is None:
            return b""
        self._control = []
        n = sum(map(len, parts)) + (len(frame) if frame is not None else 0)
        if not n:
            return b""
        end = max(now, self._tx_free_at) + self.timers.wire_time(n)
        if frame is not None:
            self._sender.transmitted(end, self.timers.ack_timeout)
            parts.append(frame)
        self._tx_free_at = end
        return b"".join(parts)

    def handle_timer(self, now: float) -> list[LinkEvent]:
        self._start(now)
        events: list[LinkEvent] = []
        t = self.timers
        if self._rx_pending_since is not None and now >= self._rx_pending_since + t.delta_r:
            self._records(self._decoder.abandon(), now, events)
            self._rx_pending_since = now if self._decoder.pending else None
        verdict = self._sender.timeout(now)
        if verdict is not ReceiveVerdict.IGNORE:
            self._failed(verdict, "timeout", events)
        if self.up and now >= self._last_rx + t.link_down_after:
            self.up = False
            self._silenced = True
            events.append(LinkDown("silence", self._hold(self._sender.discard())))
        if self._idle and now >= self._tx_free_at + t.link_test_period:
            self._sender.push(self._link_test)
        return events

    def next_deadline(self) -> float | None:
        """When `handle_timer` must next be called (None: only on bytes or application input)."""
        if not self._started:
            return None
        t = self.timers
        best = None if self._rx_pending_since is None else self._rx_pending_since + t.delta_r
        sender = self._sender
        out = sender.outstanding
        if out is not None and not out.due and out.ack_deadline is not None:  # its ACK's
            if best is None or out.ack_deadline < best:
                best = out.ack_deadline
        if self.up:
            down = self._last_rx + t.link_down_after
            if best is None or down < best:
                best = down
        if out is None and not sender.queue and not self._control:  # idle: a LINK_TEST's
            test = self._tx_free_at + t.link_test_period
            if best is None or test < best:
                best = test
        return best

    # -- internals -----------------------------------------------------------------------------
    @property
    def _idle(self) -> bool:
        return self._sender.idle and not self._control

    def _opcode(self, name: str) -> Opcode:
        opcode = self.profile.opcodes.by_name.get(name)
        if opcode is None:
            raise UsageError(f"profile {self.profile.name} has no opcode {name}")
        return opcode

    def _start(self, now: float) -> None:
        if not self._started:
            self._started = True
            # a LINK_TEST is due at once: the link announces itself when the line opens
            self._tx_free_at = now - self.timers.link_test_period
            self._last_rx = now

    def _encode(self, seq: int, message: Message) -> bytes:
        return self._codec.encode(seq, message.op, message.data)

    def _make(self, owed: Owed) -> Message:
        """The owed ALL_INFO, from the application's state now (it is going out)."""
        assert self.state_provider is not None
        statuses = bytes(self.state_provider(owed.start, owed.count))
        return Message(owed.op, statuses, "ALL_INFO")

    def _hold(self, dropped: tuple[Queued, ...]) -> tuple[Message, ...]:
        """Keep the owed answers among `dropped` for the link's recovery; return the rest."""
        for item in dropped:
            if isinstance(item, Owed) and item not in self._held:
                self._held.append(item)
        return tuple(m for m in dropped if isinstance(m, Message))

    def _records(self, records: list[Frame | Garbage], now: float, events: list[LinkEvent]) -> None:
        for rec in records:
            if isinstance(rec, Garbage):
                events.append(GarbageReceived(rec.offset, rec.raw))
                continue
            if rec.seq is not None:
                self._last_seq_seen = rec.seq
            if rec.error is not None:
                reason = _NAK_FOR_ERROR.get(rec.error, NAK_FORMAT)
                self._nak(self._last_seq_seen, reason, f"{rec.error} error", rec.raw, events)
                continue
            self._frame(rec, now, events)

    def _frame(self, rec: Frame, now: float, events: list[LinkEvent]) -> None:
        assert rec.seq is not None and rec.op is not None
        seq, op, data = rec.seq, rec.op, rec.data
        self._last_rx = now
        if not self.up:
            if self._silenced and now - self._receiver.last_time > self.timers.retry_span:
                self._receiver.forget()
            self._silenced = False
            self.up = True
            events.append(LinkUp())
            for owed in reversed(self._held):  # after our REQUEST_ALL, before the rest
                if owed not in self._sender.queue:
                    self._sender.push(owed, front=True)
            self._held.clear()
            self._request_all(now, front=True)
        if op == self._ack_op:
            if self._sender.ack(seq) is not None:
                events.append(AckReceived(seq))
            return
        if op == self._nak_op:
            reason = data[0] if data else 0
            events.append(NakReceived(seq, reason, self.profile.nak_reason_name(reason)))
            verdict = self._sender.nak()
            if verdict is not ReceiveVerdict.IGNORE:
                self._failed(verdict, "nak", events)
            return
        opcode = self.profile.opcodes.get(op)
        if opcode is None:
            self._nak(seq, NAK_FORMAT, f"unknown opcode 0x{op:04X}", rec.raw, events)
            return
        try:
            fields = opcode.parse(data)
        except PayloadError as exc:
            self._nak(seq, NAK_FORMAT, str(exc), rec.raw, events)
            return
        acceptance = self._receiver.accept(seq, now)
        self._control.append(self._codec.encode(seq, self._ack_op))
        events.append(AckSent(seq))
        if acceptance.duplicate:
            events.append(DuplicateReceived(seq, Message(op, data, opcode.name)))
            return
        if acceptance.gap_expected is not None:
            events.append(SequenceGap(acceptance.gap_expected, seq))
            self._request_all(now)
        if opcode is self._op["LINK_TEST"]:  # answered by its ACK, nothing to deliver
            return
        events.append(MessageReceived(seq, Message(op, data, opcode.name), fields))
        if opcode is self._op["REQUEST_ALL"]:
            self._answer_request_all(fields, now)

    def _answer_request_all(self, fields: dict[str, int], now: float) -> None:
        recent = self._last_request_all
        if self.state_provider is not None:
            owed = Owed(self._op["ALL_INFO"].op, fields.get("start", 0), fields.get("count", 0))
            if owed not in self._sender.queue:  # one not yet sent will carry the state anyway
                self._sender.push(owed)
        if recent is None or now - recent > self.timers.link_down_after:
            self._request_all(now)  # the peer recovered from an outage we did not see

    def _request_all(self, now: float, front: bool = False) -> None:
        opcode = self._op["REQUEST_ALL"]
        if self._sender.holds(opcode.op):
            return
        values = {f.name: (1 << 8 * f.size) - 1 if f.name == "count" else 0 for f in opcode.fields}
        self._sender.push(Message(opcode.op, opcode.build(values), opcode.name), front=front)
        self._last_request_all = now

    def _nak(
        self, seq: int, meaning: str, detail: str, raw: bytes, events: list[LinkEvent]
    ) -> None:
        reason = self._nak_reason[meaning]
        seq %= self._codec.seq_modulo
        self._control.append(self._codec.encode(seq, self._nak_op, bytes([reason])))
        events.append(NakSent(seq, reason, self.profile.nak_reason_name(reason), detail, raw))

    def _failed(self, verdict: ReceiveVerdict, cause: str, events: list[LinkEvent]) -> None:
        if verdict is ReceiveVerdict.RETRANSMIT:
            out = self._sender.outstanding
            assert out is not None
            events.append(Retransmission(out.seq, out.message, out.transmissions + 1, cause))
            return
        out, dropped = self._sender.give_up()
        discarded = self._hold(((out.owed,) if out.owed is not None else ()) + dropped)
        if self.up or out.message.op != self._op["LINK_TEST"].op:
            events.append(CommunicationError(out.seq, out.message, out.transmissions, discarded))
        if self.up:
            self.up = False
            events.append(LinkDown("communication error"))
