"""The lab in real processes over ptys and TCP (issue 5 item 8)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from ktcs_bench.station.loader import load_line
from ktcs_bench.tap.client import TapClient

from .conftest import RunningLab, request, token_for, wait_until

LINE = load_line()


def summary(lab: RunningLab, st: int) -> dict[str, Any]:
    return lab.ctc({"cmd": "show", "station": st})["summary"]  # type: ignore[no-any-return]


def span(tc: str) -> tuple[float, float]:
    t = next(t for t in LINE.all_track_circuits() if t.name == tc)
    return t.from_m, t.to_m


@contextlib.contextmanager
def route(lab: RunningLab, st: int, entry: str, exit_: str) -> Iterator[None]:
    """Set a route and wait until its signal clears at the CTC; on the way out leave the station
    as the test found it (the route cancelled, or already released by a train)."""
    result = lab.ctc({"cmd": "route", "action": "set", "station": st, "entry": entry,
                      "exit": exit_})  # fmt: skip
    assert result["ok"] and result["result"] == "accepted", result
    try:
        wait_until(f"signal {entry} of station {st} clears at the CTC",
                   lambda: summary(lab, st)["signals"][entry] != "R", timeout=30)  # fmt: skip
        yield
    finally:
        lab.ctc({"cmd": "route", "action": "cancel", "station": st, "entry": entry,
                 "exit": exit_})  # fmt: skip
        wait_until(f"route {entry}{exit_} of station {st} released",
                   lambda: f"{entry}{exit_}" not in summary(lab, st)["routes"], timeout=30)  # fmt: skip


def place(lab: RunningLab, head: float, length: float = 40.0) -> None:
    answer = lab.lab({"cmd": "status"})  # the lab answers: it is alive
    assert answer["ok"]
    request(lab.device("tc"), {"cmd": "place", "train": "T1", "head": head, "tail": head - length})


def test_ctc_route_command_sets_points_clears_signal_and_changes_atc_codes(
    running_lab: RunningLab,
) -> None:
    lab = running_lab
    codes_before = lab.status("atc18")["codes"]
    with route(lab, 18, "01", "11"):
        # indications back at the CTC: route locked, points detected and locked, signal 01 proceed
        s = summary(lab, 18)
        assert "0111" in s["routes"]
        assert s["points"]["31"] == "normal locked"
        # and the IXL itself agrees
        ixl = lab.status("ixl18")
        assert ixl["signals"]["01"] != "R"
        # the ATC's codes for the route's track circuits changed from stop to a proceed code
        codes_after = wait_until(
            "ATC codes change", lambda: (c := lab.status("atc18")["codes"]) != codes_before and c
        )
        assert codes_after["TC1853A"][1] > 0, codes_after["TC1853A"]
        # a conflicting route is rejected with its reason
        conflict = lab.ctc(
            {"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "12"}
        )
        assert not conflict["ok"] and "conflict" in conflict["result"]


def test_train_releases_the_route_section_by_section(running_lab: RunningLab) -> None:
    lab = running_lab
    with route(lab, 18, "01", "11"):
        try:
            a0, a1 = span("TC1851")
            place(lab, (a0 + a1) / 2)  # on the approach
            p0, _ = span("TC1853A")
            place(lab, p0 + 20)  # the head enters the route: the signal goes back to stop
            wait_until("signal 01 to stop once the train enters",
                       lambda: summary(lab, 18)["signals"]["01"] == "R")  # fmt: skip
            s0, s1 = span("TC1855")
            place(lab, s0 + 60, length=40)  # the tail left TC1853A: its section is released
            wait_until("TC1853A released: point 31 no longer locked",
                       lambda: summary(lab, 18)["points"]["31"] == "normal")  # fmt: skip
            # sectional release: the sections ahead of the train still hold the route
            assert "0111" in summary(lab, 18)["routes"]
            _, o1 = span("TC1857A")
            place(lab, o1 + 100, length=40)  # past the exit and the overlap
            wait_until("route 0111 fully released",
                       lambda: "0111" not in summary(lab, 18)["routes"])  # fmt: skip
        finally:
            request(lab.device("tc"), {"cmd": "remove", "train": "T1"})
            wait_until("line clear at station 18", lambda: not summary(lab, 18)["occupied"])


def _ctc_view_equals_ixl(lab: RunningLab, st: int) -> bool:
    ctc_state = lab.ctc({"cmd": "show", "station": st})["state"]
    ixl_state = lab.status(f"ixl{st}")["ctc_state"]  # code number -> state
    chart_names = list(ctc_state)
    return (
        bool(chart_names)
        and len(ctc_state) == len(ixl_state)
        and list(ctc_state.values()) == [ixl_state[k] for k in sorted(ixl_state, key=int)]
    )


def test_killing_and_restarting_the_ixl_ends_in_full_resync(running_lab: RunningLab) -> None:
    lab = running_lab
    result = lab.ctc({"cmd": "route", "action": "set", "station": 20, "entry": "01", "exit": "11"})
    assert result["ok"], result
    wait_until("route set at station 20", lambda: summary(lab, 20)["routes"])
    assert lab.lab({"cmd": "kill", "device": "ixl20"})["ok"]
    wait_until("CTC sees station 20 down", lambda: summary(lab, 20)["link"] == "down")
    assert lab.lab({"cmd": "restart", "device": "ixl20"})["ok"]
    wait_until("station 20 back and synced",
               lambda: (s := summary(lab, 20))["link"] == "up" and s["synced"])  # fmt: skip
    # a restarted IXL has lost its routes (it starts with nothing locked) -- and the CTC shows that
    wait_until("CTC view equals the IXL's state", lambda: _ctc_view_equals_ixl(lab, 20))
    assert summary(lab, 20)["routes"] == []


def test_cutting_a_type1_link_gives_most_restrictive_codes_and_signals_to_stop(
    running_lab: RunningLab,
) -> None:
    lab = running_lab
    with route(lab, 22, "01", "11"):
        stop = LINE.most_restrictive_code.code
        tap = lab.links["st22-atc"]["tap"]
        host, _, port = tap.rpartition(":")
        with TapClient((host, int(port)), timeout=10, token=token_for(tap)) as client:
            assert client.command("cut") == "cut"
        try:
            wait_until("IXL puts signal 01 to stop on the ATC link failure",
                       lambda: lab.status("ixl22")["signals"]["01"] == "R", timeout=30)  # fmt: skip
            wait_until("the CTC shows it too", lambda: summary(lab, 22)["signals"]["01"] == "R")
            codes = wait_until(
                "ATC sends the most restrictive code everywhere",
                lambda: (
                    (c := lab.status("atc22")["codes"])
                    and all(v[0] == stop for v in c.values())
                    and c
                ),
                timeout=30,
            )
            assert codes
        finally:
            with TapClient((host, int(port)), timeout=10, token=token_for(tap)) as client:
                client.command("restore")
        wait_until("links up again", lambda: lab.status("ixl22")["links"]["atc"], timeout=30)
        # until the ATC has reported every track circuit again the IXL takes them occupied (a
        # cancel then would be approach-locked); once it has, the signal clears again
        wait_until("the ATC's reports back: signal 01 clears again",
                   lambda: lab.status("ixl22")["signals"]["01"] != "R")  # fmt: skip
