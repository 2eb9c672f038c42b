"""What goes into a Type I link (`Message`) and what comes out of it (events).

Owns the link's vocabulary only: plain frozen dataclasses, no logic. Every event a `Type1Link`
returns is one of the classes listed in `LinkEvent`. An application acts on `MessageReceived`,
`CommunicationError`, `LinkDown` and `LinkUp`; the rest are for monitors, logs and tests.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, slots=True)
class Message:
    """An application message: opcode and DATA bytes (build one with `Type1Link.message()`)."""

    op: int
    data: bytes = b""
    name: str = ""

    def __repr__(self) -> str:
        label = self.name or f"0x{self.op:04X}"
        return f"Message({label}, {self.data.hex(' ')})"


@dataclass(frozen=True, slots=True)
class MessageReceived:
    """A data frame accepted and delivered, exactly once (LINK_TEST is not delivered)."""

    seq: int
    message: Message
    fields: Mapping[str, Any] = field(default_factory=dict)  # the parsed payload


@dataclass(frozen=True, slots=True)
class AckReceived:
    seq: int


@dataclass(frozen=True, slots=True)
class AckSent:
    seq: int


@dataclass(frozen=True, slots=True)
class NakReceived:
    seq: int
    reason: int
    reason_name: str


@dataclass(frozen=True, slots=True)
class NakSent:
    """We refused a frame: reason 1 CRC error, 2 frame timeout ΔR, 3 length/format/unknown op."""

    seq: int
    reason: int
    reason_name: str
    detail: str
    raw: bytes  # the refused frame's bytes as received


@dataclass(frozen=True, slots=True)
class Retransmission:
    """The outstanding frame is sent again with the same SEQ; cause is "nak" or "timeout"."""

    seq: int
    message: Message
    transmission: int
    cause: str


@dataclass(frozen=True, slots=True)
class DuplicateReceived:
    """A frame repeating the last accepted SEQ: ACKed again, not delivered."""

    seq: int
    message: Message


@dataclass(frozen=True, slots=True)
class SequenceGap:
    """A data frame's SEQ is not the one after the last accepted (the peer lost frames)."""

    expected: int
    received: int


@dataclass(frozen=True, slots=True)
class CommunicationError:
    """`transmissions` sends of `message` without ACK. The link drops it and the messages queued
    behind it (`discarded`): state is rebuilt by REQUEST_ALL/ALL_INFO when the link recovers."""

    seq: int
    message: Message
    transmissions: int
    discarded: tuple[Message, ...] = ()


@dataclass(frozen=True, slots=True)
class LinkUp:
    """A valid frame arrived on a link that was down; REQUEST_ALL has been queued."""


@dataclass(frozen=True, slots=True)
class LinkDown:
    """reason: "silence" (nothing valid for link_down_after) or "communication error"."""

    reason: str
    discarded: tuple[Message, ...] = ()


@dataclass(frozen=True, slots=True)
class GarbageReceived:
    """Bytes that belong to no frame (the receiver resynchronised past them)."""

    offset: int
    raw: bytes


LinkEvent = (
    MessageReceived
    | AckReceived
    | AckSent
    | NakReceived
    | NakSent
    | Retransmission
    | DuplicateReceived
    | SequenceGap
    | CommunicationError
    | LinkUp
    | LinkDown
    | GarbageReceived
)
