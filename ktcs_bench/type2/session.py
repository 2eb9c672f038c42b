"""The sans-I/O core shared by both ends of a Type II link (SPEC §4): framing, SEQ, NAK and
retransmission, heartbeat and T_MAX supervision. No sockets, no clocks: the adapter feeds bytes and
`now`, and collects `data_to_send()`, the returned events and `next_deadline()`.

Reliability model (TCP underneath, so frames are only lost or damaged by something in the path):

* Every frame, HEARTBEAT and NAK included, takes the next SEQ of its direction; the sender keeps the
  last `history_size` frames.
* A receiver never acts on a bad frame (CRC, length/format, unknown opcode, stray bytes). It answers
  NAK(reason, SEQ it expected) and then discards everything until that SEQ arrives again, so frames
  are acted on exactly once and in order. A frame behind the expected SEQ is a duplicate (dropped);
  one ahead of it is a SEQ gap (reported; the CTC side then asks REQUEST_ALL).
* On NAK(s) the sender goes back: it resends s and every frame after it. A fourth NAK for the same
  frame (after `retry_count` retransmissions), or a NAK for a frame it no longer holds, closes the
  connection -- the IXL reconnects and resends its full state.
"""

from __future__ import annotations

import enum
import struct
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from ktcs_bench.codec import Frame, FrameCodec, Garbage, StreamDecoder, get_profile
from ktcs_bench.codec.opcodes import Opcode, PayloadError
from ktcs_bench.errors import UsageError
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.config import Type2Config

# The NAK reasons by their names in the profile's `nak_reasons`; the numbers are the profile's.
NAK_CRC = "crc error"
NAK_FORMAT = "length/format error"
NAK_UNKNOWN_OPCODE = "unknown opcode"

OP_IDENT = 0x01
OP_INDICATION = 0x10
OP_CONTROL = 0x20
OP_CONTROL_RESULT = 0x21
OP_REQUEST_ALL = 0x30
OP_HEARTBEAT = 0x40
OP_NAK = 0x15

SUB_IDENT_REQUEST, SUB_IDENT_ACCEPTED, SUB_IDENT_REFUSED = 0, 1, 2
SUB_CHANGE, SUB_FULL_PART, SUB_FULL_LAST = 0, 1, 2
SUB_ACCEPTED, SUB_REJECTED = 0, 1

_SEQ_MOD = 256
_HALF = _SEQ_MOD // 2
_U8 = struct.Struct("<B")


class SessionState(enum.Enum):
    IDENTIFYING = "identifying"
    OPEN = "open"
    CLOSED = "closed"


@dataclass(slots=True)
class _Sent:
    frame: bytes
    retries: int = 0


class FrameRefused(Exception):
    """Raised by a handler: the frame is not acted on and is NAKed with `reason` (as the profile's
    `nak_reasons` names it: `NAK_FORMAT`, ...)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


class SessionDropped(Exception):
    """Raised by a handler after it closed the session: stop processing this frame."""


Handler = Callable[[Frame, float], None]


class Type2Session:
    """State common to both sides. Subclasses register handlers per opcode in `_handlers`."""

    role = "?"

    def __init__(self, now: float, config: Type2Config | None = None) -> None:
        self.config = config or Type2Config()
        self.profile = get_profile(self.config.profile)
        self.codec = FrameCodec(self.profile)
        self._decoder = StreamDecoder(self.profile)
        self._nak_reason = {
            meaning: self.profile.nak_reason(meaning)
            for meaning in (NAK_CRC, NAK_FORMAT, NAK_UNKNOWN_OPCODE)
        }
        ops = self.profile.opcodes.by_name
        self.op_indication: Opcode = ops["INDICATION"]
        self.op_control: Opcode = ops["CONTROL"]
        self.op_ident: Opcode = ops["IDENT"]
        self.op_result: Opcode = ops["CONTROL_RESULT"]
        self.max_items = self.profile.max_data // self.op_indication.item_size
        self.state = SessionState.IDENTIFYING
        self.close_reason: str | None = None
        self._out = bytearray()
        self._events: list[ev.SessionEvent] = []
        self._tx_seq = 0
        self._history: OrderedDict[int, _Sent] = OrderedDict()
        self._rx_expected: int | None = None
        self._awaiting: int | None = None  # SEQ refused and not yet received again
        self._awaiting_reason = 0
        self._nak_at = 0.0
        self._naks_for_awaiting = 0
        self._opened_at = now
        self._last_tx = now
        self._last_rx = now
        self._handlers: dict[int, Handler] = {
            OP_HEARTBEAT: self._on_heartbeat,
            OP_NAK: self._on_nak,
        }
        self.frames_sent = 0
        self.frames_received = 0

    # -- public API --------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self.state is SessionState.CLOSED

    @property
    def identified(self) -> bool:
        return self.state is SessionState.OPEN

    def data_to_send(self) -> bytes:
        """Bytes to write to the transport now (empty when nothing is due)."""
        out = bytes(self._out)
        self._out.clear()
        return out

    def receive_data(self, data: bytes, now: float) -> list[ev.SessionEvent]:
        """Feed bytes from the transport; returns the events they caused."""
        if self.closed or not data:
            return self._take_events()
        self._last_rx = now
        for rec in self._decoder.feed(data):
            if self.closed:
                break
            if isinstance(rec, Garbage):
                self._bad(None, self._nak_reason[NAK_FORMAT], f"{len(rec.raw)} stray bytes", now)
            elif rec.error is not None:
                reason = self._nak_reason[NAK_CRC if rec.error == "crc" else NAK_FORMAT]
                self._bad(rec.seq, reason, f"{rec.error} error", now)
            else:
                self._good(rec, now)
        return self._take_events()

    def connection_lost(self, now: float) -> list[ev.SessionEvent]:
        """The transport closed under us."""
        self._close("connection lost")
        return self._take_events()

    def close(self, reason: str = "closed locally") -> list[ev.SessionEvent]:
        self._close(reason)
        return self._take_events()

    def next_deadline(self) -> float | None:
        """When `handle_timer` must next be called (None once closed)."""
        if self.closed:
            return None
        cfg = self.config
        due = self._last_rx + cfg.t_max
        if self.state is SessionState.IDENTIFYING:
            due = min(due, self._opened_at + cfg.ident_timeout)
        else:
            due = min(due, self._last_tx + cfg.heartbeat_period)
        if self._awaiting is not None:
            due = min(due, self._nak_at + cfg.nak_repeat)
        return due

    def handle_timer(self, now: float) -> list[ev.SessionEvent]:
        if self.closed:
            return self._take_events()
        cfg = self.config
        # each test is the sum next_deadline() gives, so a call at that deadline always sees it
        # due (now - last >= period can round the other way, leaving the deadline at `now`)
        if now >= self._last_rx + cfg.t_max:
            self._events.append(ev.LinkDown(now - self._last_rx))
            self._close(f"link down: nothing received for {now - self._last_rx:.1f} s")
            return self._take_events()
        if self.state is SessionState.IDENTIFYING and now >= self._opened_at + cfg.ident_timeout:
            self._close(f"no IDENT exchange within {cfg.ident_timeout:g} s")
            return self._take_events()
        if self._awaiting is not None and now >= self._nak_at + cfg.nak_repeat:
            self._nak_again(now)
            if self.closed:
                return self._take_events()
        # no HEARTBEAT before the IDENT exchange: the IXL's IDENT is the first frame of a session
        if self.state is SessionState.OPEN and now >= self._last_tx + cfg.heartbeat_period:
            self._send(OP_HEARTBEAT, 0, b"", now)
        return self._take_events()

    # -- sending -----------------------------------------------------------------------------
    def _send(self, op: int, sub: int, data: bytes, now: float) -> int:
        if self.closed:
            raise UsageError(f"Type II {self.role} session is closed ({self.close_reason})")
        seq = self._tx_seq
        frame = self.codec.encode(seq, op, data, sub)
        self._tx_seq = (seq + 1) % _SEQ_MOD
        history = self._history
        history.pop(seq, None)
        history[seq] = _Sent(frame)
        if len(history) > self.config.history_size:
            history.popitem(last=False)
        self._out += frame
        self._last_tx = now
        self.frames_sent += 1
        return seq

    def _send_items(
        self, op: Opcode, items: list[ev.Item], subs: tuple[int, int], now: float
    ) -> int:
        """Send items in frames of at most `max_items`; `subs` = (sub for a part, sub for the last)."""
        n = self.max_items
        frames = max(1, -(-len(items) // n))
        pack = op.pack_items
        for k in range(frames):
            chunk = items[k * n : (k + 1) * n]
            sub = subs[1] if k == frames - 1 else subs[0]
            self._send(op.op, sub, pack(chunk), now)
        return frames

    def _nak(self, reason: int, refused: int, now: float) -> None:
        self._send(OP_NAK, reason, _U8.pack(refused), now)
        self._nak_at = now
        self._naks_for_awaiting += 1

    def _nak_again(self, now: float) -> None:
        assert self._awaiting is not None
        if self._naks_for_awaiting > self.config.retry_count + 1:
            self._close(f"SEQ {self._awaiting} still refused after {self._naks_for_awaiting} NAKs")
            return
        self._nak(self._awaiting_reason, self._awaiting, now)

    # -- receiving ---------------------------------------------------------------------------
    def _bad(self, hint_seq: int | None, reason: int, detail: str, now: float) -> None:
        if self._awaiting is None:
            refused = self._rx_expected
            if refused is None:
                refused = hint_seq if hint_seq is not None else 0
            self._awaiting = refused
            self._awaiting_reason = reason
            self._naks_for_awaiting = 0
            self._events.append(ev.BadFrameReceived(reason, refused, detail, True))
            self._nak(reason, refused, now)
            return
        # Already waiting for a retransmission: NAK again only for the awaited frame itself.
        again = hint_seq == self._awaiting or now - self._nak_at >= self.config.nak_repeat
        self._events.append(ev.BadFrameReceived(reason, self._awaiting, detail, again))
        if again:
            self._awaiting_reason = reason
            self._nak_again(now)

    def _good(self, frame: Frame, now: float) -> None:
        seq = frame.seq
        assert seq is not None and frame.op is not None
        if self._awaiting is not None:
            if seq != self._awaiting:
                if now - self._nak_at >= self.config.nak_repeat:
                    self._nak_again(now)
                return  # not acted on: it will come again after the awaited frame
            self._awaiting = None
        elif self._rx_expected is not None and seq != self._rx_expected:
            ahead = (seq - self._rx_expected) % _SEQ_MOD
            if ahead >= _HALF:
                return  # a duplicate from a go-back we no longer need
            self._events.append(ev.SequenceGap(self._rx_expected, seq))
            self._on_gap(now)
        handler = self._handlers.get(frame.op)
        try:
            if handler is None:
                raise FrameRefused(NAK_UNKNOWN_OPCODE, f"opcode {frame.op:#04x} not handled here")
            handler(frame, now)  # handlers validate everything before they act
        except SessionDropped:
            return
        except (FrameRefused, PayloadError) as exc:
            reason = self._nak_reason[exc.reason if isinstance(exc, FrameRefused) else NAK_FORMAT]
            self._rx_expected = seq
            self._awaiting = seq
            self._awaiting_reason = reason
            self._naks_for_awaiting = 0
            self._events.append(ev.BadFrameReceived(reason, seq, str(exc), True))
            self._nak(reason, seq, now)
            return
        self._rx_expected = (seq + 1) % _SEQ_MOD
        self.frames_received += 1

    def _on_gap(self, now: float) -> None:
        """Hook: the CTC asks REQUEST_ALL; the IXL has nothing to ask for."""

    def _require_open(self, frame: Frame) -> None:
        if self.state is not SessionState.OPEN:
            self._close(f"opcode {frame.op:#04x} before the IDENT exchange completed")
            raise SessionDropped

    def _expect_sub(self, frame: Frame, *subs: int) -> int:
        sub = frame.sub if frame.sub is not None else 0
        if sub not in subs:
            raise FrameRefused(NAK_FORMAT, f"opcode {frame.op:#04x} with sub {sub} not valid here")
        return sub

    def _expect_empty(self, frame: Frame) -> None:
        if frame.data_end != frame.data_start:
            raise FrameRefused(NAK_FORMAT, f"opcode {frame.op:#04x} carries no DATA")

    def _items(self, op: Opcode, frame: Frame) -> tuple[ev.Item, ...]:
        return tuple((c, s) for c, s in op.items_of(frame.data))

    def _on_heartbeat(self, frame: Frame, now: float) -> None:
        self._expect_sub(frame, 0)
        self._expect_empty(frame)

    def _on_nak(self, frame: Frame, now: float) -> None:
        data = frame.data
        if len(data) != 1:
            raise FrameRefused(NAK_FORMAT, f"NAK carries {len(data)} bytes, not 1")
        refused = data[0]
        self._events.append(ev.NakReceived(refused, frame.sub or 0))
        if refused == self._tx_seq:
            return  # the frame it expects has not been sent yet: nothing to resend
        entry = self._history.get(refused)
        if entry is None:
            self._close(f"NAK for SEQ {refused}, a frame no longer held")
            return
        retries = entry.retries + 1
        if retries > self.config.retry_count:
            self._close(f"SEQ {refused} refused after {self.config.retry_count} retransmissions")
            return
        entry.retries = retries
        # Go back: resend the refused frame and everything after it, in order.
        frames = 0
        seq = refused
        while seq != self._tx_seq:
            held = self._history.get(seq)
            if held is not None:
                self._out += held.frame
                frames += 1
            seq = (seq + 1) % _SEQ_MOD
        self._last_tx = now
        self._events.append(ev.Retransmission(refused, retries, frames))

    # -- helpers -----------------------------------------------------------------------------
    def _close(self, reason: str) -> None:
        if self.closed:
            return
        self.state = SessionState.CLOSED
        self.close_reason = reason
        self._events.append(ev.Closed(reason))

    def _take_events(self) -> list[ev.SessionEvent]:
        out = self._events
        self._events = []
        return out

    @staticmethod
    def _as_items(items: Iterable[tuple[int, int] | list[int]]) -> list[ev.Item]:
        return [(int(c), int(s)) for c, s in items]
