"""Type II link settings (SPEC §4): the timers and limits a signalling engineer sets per link.

Times are in seconds of whatever clock the adapter feeds the session (wall or virtual).
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.errors import UsageError

# SEQ_NO is one byte, so a receiver can only tell "old" from "ahead" within half the space;
# keeping more than half of it for retransmission would make a go-back ambiguous.
MAX_HISTORY = 128


@dataclass(frozen=True, slots=True)
class Type2Config:
    """Per-link settings; the defaults are SPEC §4's."""

    heartbeat_period: float = 1.0
    """A HEARTBEAT goes out when a direction has carried nothing for this long."""
    t_max: float = 3.0
    """T_MAX: silence (no byte received) after which the link is down and the connection closed."""
    retry_count: int = 3
    """Retransmissions of one refused frame before the sender gives up and closes."""
    ident_timeout: float = 3.0
    """Time from connection to a completed IDENT exchange (either side closes after it)."""
    nak_repeat: float = 1.0
    """A receiver still waiting for a refused frame NAKs it again after this long."""
    history_size: int = MAX_HISTORY
    """Sent frames kept for retransmission (go-back from the refused SEQ)."""
    version: int = 1
    """Protocol version carried in IDENT."""
    profile: str = "ktcs-type2"
    """Wire profile name (protocols/type2.yaml)."""

    def __post_init__(self) -> None:
        for name in ("heartbeat_period", "t_max", "ident_timeout", "nak_repeat"):
            if not getattr(self, name) > 0:
                raise UsageError(f"Type II {name} must be positive, not {getattr(self, name)}")
        if self.t_max <= self.heartbeat_period:
            raise UsageError("Type II t_max must exceed the heartbeat period")
        if not 0 <= self.retry_count <= 16:
            raise UsageError(f"Type II retry_count must be 0..16, not {self.retry_count}")
        if not 1 <= self.history_size <= MAX_HISTORY:
            raise UsageError(f"Type II history_size must be 1..{MAX_HISTORY}")
        if not 0 <= self.version <= 255:
            raise UsageError(f"Type II version must be a byte, not {self.version}")
