"""Signal aspects: which aspect a cleared route earns, and what the lamps prove.

A route's data gives its best aspect; it is downgraded by what its exit signal shows (exit at
stop: caution Y; exit at caution: reduce YG) and fitted to the aspects the signal has. The IXL
commands one aspect per signal; the trackside reports which lamp is lit (LPS) and lamp failures
(LFI), so the indication to the CTC is what the lamps prove, not what was asked.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ktcs_bench.station.model import ASPECT_ORDER, Signal


def fit(signal: Signal, wanted: str) -> str:
    """The least restrictive aspect the signal has that is no less restrictive than `wanted`."""
    rank = ASPECT_ORDER.index(wanted)
    usable = [a for a in signal.aspects if ASPECT_ORDER.index(a) <= rank]
    return max(usable, key=ASPECT_ORDER.index) if usable else "R"


def downgrade(best: str, exit_shows: str | None) -> str:
    """The aspect a route may show given its exit signal (None: the exit has no lamps)."""
    if best in ("R", "W") or exit_shows is None:
        return best
    if exit_shows == "R":
        cap = "Y"
    elif exit_shows in ("Y", "W"):
        cap = "YG"
    else:
        cap = "G"
    return best if ASPECT_ORDER.index(best) <= ASPECT_ORDER.index(cap) else cap


@dataclass
class SignalState:
    signal: Signal
    commanded: str = "R"
    stop_held: bool = False  # CTC "signal stop" (SSC=1)
    lamp_bits: dict[str, int] = field(default_factory=dict)  # aspect -> LPS bit
    lamp_reported: bool = False
    lamp_failed: bool = False

    @property
    def lit(self) -> str | None:
        """The proved-lit aspect (the least restrictive if several); None when dark."""
        on = [a for a in self.signal.aspects if self.lamp_bits.get(a, 0) == 1]
        return max(on, key=ASPECT_ORDER.index) if on else None

    def shown(self) -> str | None:
        """What the CTC is told the signal shows: the lamps once reported, else the command."""
        return self.lit if self.lamp_reported else self.commanded

    @property
    def proceed(self) -> bool:
        """Commanded to proceed and not contradicted by the lamps (what the ATC is told)."""
        if self.commanded == "R":
            return False
        return not self.lamp_reported or self.lit not in (None, "R")
