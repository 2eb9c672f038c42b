"""A track relay: reports its track circuit occupied while a train shunts it, unless faulted.

Faults (SPEC §6.3): "failed_occupied" (relay dropped: the safe-side failure) and "failed_clear"
(relay stuck up under a train: the wrong-side failure the bench injects to test detection).
"""

from __future__ import annotations

from dataclasses import dataclass

FAULTS = ("failed_occupied", "failed_clear")


@dataclass
class TrackRelay:
    name: str
    train: bool = False  # a train is in the track circuit
    fault: str | None = None

    @property
    def occupied(self) -> bool:
        if self.fault == "failed_occupied":
            return True
        if self.fault == "failed_clear":
            return False
        return self.train
