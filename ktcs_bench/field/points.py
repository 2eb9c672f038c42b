"""A point machine: throws in `throw_time_s`, shows SNR/SRN while moving, loses detection on fault.

Faults: "detection" (the detection contacts open: no indication at all, whatever the blades do),
"jammed" (the machine runs but the blades never reach the other position: it keeps showing
the moving indication) and "crossed" (a wrong-side failure, the detection wired the wrong way
round: blades lying normal are reported reverse and the other way about -- what the whole-system
search injects to see a train sent where the interlocking did not mean it to go). A throw reversed half-way takes as long to come back as it had run.
A train trailing the point against its blades forces them over to its leg (`trail`): the
detection is lost ("trailed", like "detection") until a fault clear repairs the point.
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.station.model import Point, PointPosition

FAULTS = ("detection", "jammed", "crossed")
TRAILED = "trailed"
"""The fault a trailing train leaves (not injected: `trail`)."""


@dataclass
class PointMachine:
    point: Point
    position: PointPosition | None = "normal"  # None while between positions
    target: PointPosition = "normal"
    started_at: float | None = None
    arrive_at: float | None = None
    fault: str | None = None

    @property
    def moving(self) -> bool:
        return self.arrive_at is not None

    def command(self, target: PointPosition, now: float) -> bool:
        """Demand a position; True when this starts (or reverses) a throw."""
        if target == self.target and (self.moving or self.position == target):
            return False
        throw = self.point.throw_time_s
        if self.moving and self.started_at is not None:
            run = min(now - self.started_at, throw)  # come back the way it went
        else:
            run = throw
        self.target = target
        self.position = None
        self.started_at = now
        self.arrive_at = now + run
        return True

    def handle_timer(self, now: float) -> bool:
        """Finish a throw that is due; True when the blades arrived."""
        if self.arrive_at is None or now < self.arrive_at or self.fault == "jammed":
            return False
        self.position = self.target
        self.arrive_at = None
        self.started_at = None
        return True

    def trail(self, leg: PointPosition) -> None:
        """A train trailed the point from `leg`: the blades are forced over to it, and the
        detection is lost until the fault is cleared."""
        self.position = self.target = leg
        self.started_at = self.arrive_at = None
        self.fault = TRAILED

    def blades(self) -> str:
        """Where the blades are, whatever detection says: normal, reverse, moving, or none
        (stopped between positions)."""
        if self.position is not None:
            return self.position
        return "moving" if self.moving else "none"

    def next_deadline(self) -> float | None:
        return None if self.fault == "jammed" else self.arrive_at

    def bits(self) -> dict[str, int]:
        """The four Table 3 indications: SNI, SRN, SRI, SNR."""
        out = {"SNI": 0, "SRN": 0, "SRI": 0, "SNR": 0}
        if self.fault in ("detection", TRAILED):
            return out
        position = self.position
        if self.fault == "crossed" and position is not None:
            position = "reverse" if position == "normal" else "normal"
        if position == "normal":
            out["SNI"] = 1
        elif position == "reverse":
            out["SRI"] = 1
        elif self.target == "normal":
            out["SRN"] = 1
        else:
            out["SNR"] = 1
        return out
