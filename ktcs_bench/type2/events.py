"""Events the Type II sessions hand to their adapter (what happened on the link, in order).

Items are (code number, state/value) pairs; code numbers are 1-based chart positions.
"""

from __future__ import annotations

from dataclasses import dataclass

Item = tuple[int, int]


@dataclass(frozen=True, slots=True)
class IdentRequested:
    """CTC side: the IXL named itself; answer with `accept()` or `refuse()`."""

    station: int
    version: int


@dataclass(frozen=True, slots=True)
class IdentAccepted:
    """IXL side: the CTC accepted us; the full state is due now (`send_full_state`)."""

    station: int


@dataclass(frozen=True, slots=True)
class IdentRefused:
    """IXL side: the CTC refused us; the session is closed."""

    station: int


@dataclass(frozen=True, slots=True)
class IndicationsChanged:
    """CTC side: change indications (INDICATION sub 0), in the order they were sent."""

    items: tuple[Item, ...]


@dataclass(frozen=True, slots=True)
class FullState:
    """CTC side: a complete full-state dump (every part up to the last), in chart order."""

    items: tuple[Item, ...]
    parts: int


@dataclass(frozen=True, slots=True)
class ControlRequested:
    """IXL side: one CONTROL message; answer each item with `send_control_result`."""

    items: tuple[Item, ...]


@dataclass(frozen=True, slots=True)
class ControlAnswered:
    """CTC side: the IXL answered one control code (a CONTROL_RESULT item)."""

    code: int
    accepted: bool
    reason: int
    reason_name: str


@dataclass(frozen=True, slots=True)
class FullStateRequested:
    """IXL side: the CTC asked REQUEST_ALL; the full state is due now."""


@dataclass(frozen=True, slots=True)
class SequenceGap:
    """A good frame arrived with a SEQ past the one expected (frames were lost)."""

    expected: int
    received: int


@dataclass(frozen=True, slots=True)
class BadFrameReceived:
    """A frame (or garbage) failed CRC/format/opcode checks; it was not acted on and was NAKed."""

    reason: int
    refused_seq: int
    detail: str
    nak_sent: bool


@dataclass(frozen=True, slots=True)
class NakReceived:
    """The peer refused one of our frames."""

    refused_seq: int
    reason: int


@dataclass(frozen=True, slots=True)
class Retransmission:
    """Frames from `seq` on were sent again (`attempt` = 1..retry_count for that SEQ)."""

    seq: int
    attempt: int
    frames: int


@dataclass(frozen=True, slots=True)
class LinkDown:
    """Nothing received for T_MAX; the session closes right after."""

    silent_for: float


@dataclass(frozen=True, slots=True)
class Closed:
    """The session is over; the adapter flushes `data_to_send()` and closes the transport."""

    reason: str


SessionEvent = (
    IdentRequested
    | IdentAccepted
    | IdentRefused
    | IndicationsChanged
    | FullState
    | ControlRequested
    | ControlAnswered
    | FullStateRequested
    | SequenceGap
    | BadFrameReceived
    | NakReceived
    | Retransmission
    | LinkDown
    | Closed
)
