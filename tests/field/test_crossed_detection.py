"""The wrong-side point fault `crossed` (field/points.py): the detection reports the other end
position than the blades lie in, and a clear puts it right."""

from __future__ import annotations

from ktcs_bench.field.points import FAULTS, PointMachine
from ktcs_bench.station import load_line

POINT = load_line().station(18).point("31")


def test_crossed_detection_reports_the_other_end_position_of_the_blades() -> None:
    assert "crossed" in FAULTS
    pm = PointMachine(POINT)
    assert pm.bits()["SNI"] == 1
    pm.fault = "crossed"
    assert pm.bits() == {"SNI": 0, "SRN": 0, "SRI": 1, "SNR": 0}, "blades normal, reported reverse"
    assert pm.blades() == "normal"
    pm.command("reverse", 0.0)
    pm.handle_timer(100.0)
    assert pm.blades() == "reverse"
    assert pm.bits() == {"SNI": 1, "SRN": 0, "SRI": 0, "SNR": 0}, "blades reverse, reported normal"
    pm.fault = None
    assert pm.bits()["SRI"] == 1
