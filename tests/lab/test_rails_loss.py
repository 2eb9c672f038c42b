"""Losing the rails is fail-safe, in the real lab (issue 12 item 5; SPEC §6.2 invariant 3, §6.4).

A train stands on TC1855 at station 18. The track-circuit emulator (the rails) is killed: the ATC
and the trackside I/O no longer know where trains are, so they report every track circuit occupied
and a route set afterwards (01 -> 12, clear of the train before) must not clear signal 01. When
the track-circuit emulator is restarted (`lab restart tc`) the rails report again -- a fresh
emulator knows no train -- the line is clear and the same route clears signal 01.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.station.loader import load_line

from .conftest import RunningLab, request, start_lab, wait_until

LINE = load_line()
OWN_18 = [t.name for t in LINE.view(18).track_circuits]


def summary(lab: RunningLab, st: int) -> dict[str, Any]:
    return lab.ctc({"cmd": "show", "station": st})["summary"]  # type: ignore[no-any-return]


def route_0112(lab: RunningLab, action: str = "set") -> dict[str, Any]:
    return lab.ctc({"cmd": "route", "action": action, "station": 18, "entry": "01", "exit": "12"})


def test_without_the_rails_every_track_circuit_is_occupied_until_they_are_back(
    tmp_path: Path,
) -> None:
    with start_lab(tmp_path, "railslab") as lab:
        tc1855 = next(t for t in LINE.all_track_circuits() if t.name == "TC1855")
        mid = (tc1855.from_m + tc1855.to_m) / 2
        place = {"cmd": "place", "train": "T1", "head": mid + 20, "tail": mid - 20, "track": "1"}
        assert request(lab.device("tc"), place)["ok"]
        wait_until("the train on TC1855 reported at the CTC",
                   lambda: summary(lab, 18)["occupied"] == ["TC1855"])  # fmt: skip
        wait_until("the trackside has the rails: TC1853A clear, TC1855 occupied",
                   lambda: (s := lab.status("io18")["state"])["TC1853A"] == 0 and s["TC1855"])  # fmt: skip

        assert lab.lab({"cmd": "kill", "device": "tc"})["ok"]
        # the ATC and the trackside go fail-safe: every track circuit they report is occupied
        wait_until("the ATC reports every track circuit occupied",
                   lambda: all(lab.status("atc18")["state"].values()))  # fmt: skip
        wait_until("the trackside's relays all report occupied",
                   lambda: all(lab.status("io18")["state"][t] for t in OWN_18))  # fmt: skip
        wait_until("the IXL and the CTC take the whole station occupied",
                   lambda: sorted(summary(lab, 18)["occupied"]) == sorted(OWN_18))  # fmt: skip
        stop = LINE.most_restrictive_code.code
        assert all(code[0] == stop for code in lab.status("atc18")["codes"].values())
        # a route over track circuits that were clear before the rails went is refused
        answer = route_0112(lab)
        assert not answer["ok"] and answer["reason"] == Reason.TRACK_OCCUPIED, answer
        assert "occupied" in answer["result"]
        assert lab.status("ixl18")["signals"]["01"] == "R"
        assert summary(lab, 18)["signals"]["01"] == "R"
        assert "0112" not in summary(lab, 18)["routes"]

        assert lab.lab({"cmd": "restart", "device": "tc"})["ok"]
        wait_until("the ATC has the rails again and reports the line clear",
                   lambda: (s := lab.status("atc18"))["rails"] and not any(s["state"].values()),
                   timeout=60)  # fmt: skip
        wait_until("the trackside's relays clear",
                   lambda: not any(lab.status("io18")["state"][t] for t in OWN_18))  # fmt: skip
        wait_until("station 18 clear at the CTC", lambda: not summary(lab, 18)["occupied"])
        answer = route_0112(lab)
        assert answer["ok"], answer
        wait_until("signal 01 clears to Y", lambda: summary(lab, 18)["signals"]["01"] == "Y")
        assert lab.status("ixl18")["signals"]["01"] == "Y"
