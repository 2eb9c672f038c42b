"""The IXL's view of one point: what it demands of the trackside and what detection came back.

The demand is a level (PNC/PRC: "normal wanted" / "reverse wanted"), as a point control relay
holds its position; the point machine moves whenever its position differs. Detection arrives as
the four Table 3 bits SNI/SRN/SRI/SNR; none set means detection is lost (point failed). A call (a
change of the demand) is answered by the trackside with the point's indications; until that
answer comes the point counts as moving to the called position, whatever was reported before:
a report that already showed the called position (a detection fault reporting the blades the
wrong way round, a restarted interlocking's first call) would otherwise prove a route over blades
about to move.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ktcs_bench.station.model import Point, PointPosition

Detection = Literal["normal", "reverse", "to_normal", "to_reverse", "none"]
BITS = ("SNI", "SRN", "SRI", "SNR")


def detection_from_bits(bits: dict[str, int]) -> Detection:
    """Decode SNI/SRN/SRI/SNR; contradictory bits (normal and reverse at once) count as lost."""
    normal, reverse = bits.get("SNI", 0) == 1, bits.get("SRI", 0) == 1
    if normal and reverse:
        return "none"
    if normal:
        return "normal"
    if reverse:
        return "reverse"
    if bits.get("SNR", 0) == 1:
        return "to_reverse"
    if bits.get("SRN", 0) == 1:
        return "to_normal"
    return "none"


@dataclass
class PointState:
    point: Point
    # None: nothing demanded (PNC and PRC off, the machine stays where it lies) -- a restarted
    # interlocking, until a route or a control demands the point with its checks: neither its
    # default nor the detected position, which a wrong-side detection fault makes a throw under
    # a train (see ixl.interlocking)
    demanded: PointPosition | None = "normal"
    bits: dict[str, int] = field(default_factory=dict)  # last reported by the trackside
    # False from a change of the demand until the trackside reports the point again (it answers
    # every call): a report from before the call is no proof of where the call left the blades
    answered: bool = True

    def call(self, position: PointPosition) -> None:
        """Demand `position`; the detection proves nothing until the trackside answers."""
        self.demanded = position
        self.answered = False

    @property
    def reported(self) -> Detection:
        return detection_from_bits(self.bits)
