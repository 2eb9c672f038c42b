"""The Type I link (SPEC §3): ARQ, timers and link state over the Type I framing, sans I/O.

Owns: `Type1Link` (link.py), its ARQ state machine (arq.py), timers and settings (config.py) and
its events (events.py). Must not touch: sockets, ptys, clocks -- drivers in `ktcs_bench.transport`
bind a link to a wire and a clock.
"""

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
from ktcs_bench.type1.link import StateProvider, Type1Link

__all__ = [
    "AckReceived",
    "AckSent",
    "CommunicationError",
    "DuplicateReceived",
    "LinkEvent",
    "GarbageReceived",
    "LinkConfig",
    "LinkDown",
    "LinkTimers",
    "LinkUp",
    "Message",
    "MessageReceived",
    "NakReceived",
    "NakSent",
    "Retransmission",
    "SequenceGap",
    "StateProvider",
    "Type1Link",
]
