"""A signal head: lights the commanded aspect, falls back to a more restrictive one on lamp failure.

With the commanded aspect's lamp failed the head shows the next more restrictive aspect it can
still light; with the red lamp failed as well it goes dark. Any failed lamp is reported (LFI).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ktcs_bench.station.model import ASPECT_ORDER, Signal


@dataclass
class SignalHead:
    signal: Signal
    commanded: str = "R"
    failed: set[str] = field(default_factory=set)

    def command_bits(self, bits: dict[str, int]) -> None:
        """One-hot SGC bits -> the commanded aspect; none or several set -> the most restrictive."""
        on = [a for a in self.signal.aspects if bits.get(a, 0) == 1]
        self.commanded = min(on, key=ASPECT_ORDER.index) if len(on) == 1 else "R"

    def lit(self) -> str | None:
        """The aspect actually lit, or None when the head is dark."""
        rank = ASPECT_ORDER.index(self.commanded)
        candidates = sorted(
            (a for a in self.signal.aspects if ASPECT_ORDER.index(a) <= rank),
            key=ASPECT_ORDER.index,
            reverse=True,
        )
        for a in candidates:
            if a not in self.failed:
                return a
        return None

    @property
    def lamp_failure(self) -> bool:
        return bool(self.failed)
