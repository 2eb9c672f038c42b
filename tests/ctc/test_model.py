"""The CTC's model (pure): one reading of a station's indications behind both the console's
picture and `ctc show`'s summary, and operator commands as the control codes the interlocking
reads."""

from __future__ import annotations

import pytest

from ktcs_bench.ctc.log import CommandLog, command_words
from ktcs_bench.ctc.model import UNKNOWN, CtcModel
from ktcs_bench.ctc.tables import IndicationTable
from ktcs_bench.errors import UsageError
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.loader import load_line
from ktcs_bench.station_codes.stations import link_charts

LINE = load_line()


def table_of(rig: StationRig, number: int) -> IndicationTable:
    """The CTC's table for `rig` as a live, synced link would have brought it (code numbers as
    the interlocking numbers them)."""
    chart, _ = link_charts(rig.view, "ixl_to_ctc")
    state = {chart.number_of(k): v for k, v in rig.ctc.items()}
    return IndicationTable(number, state, connected=True, synced=True)


def test_picture_and_summary_are_one_reading_of_the_table() -> None:
    rig = StationRig(LINE.view(20), mode=Mode.CENTER)
    assert rig.control("RSC200111").accepted
    assert rig.control("SRC2032").accepted
    rig.advance(0.5)  # point 32 on its way
    rig.occupy("TC2063")  # beyond the route: its signal stays clear
    model = CtcModel(LINE).station(20)
    table = table_of(rig, 20)
    picture = model.picture(table.state, True, True)
    summary = model.summary(table)
    assert summary["known"] and summary["mode"] == picture["mode"] == "center"
    assert summary["routes"] == [r for r, v in picture["routes"].items() if v["set"]] == ["0111"]
    for p, shown in picture["points"].items():
        assert summary["points"][p] == shown["position"] + (" locked" if shown["locked"] else "")
    assert picture["points"]["32"]["position"] == "to_reverse"
    assert summary["points"]["33"] == "normal locked"
    for s, aspect in summary["signals"].items():
        assert aspect == picture["signals"][s]["aspect"]
    assert summary["signals"]["01"] in ("Y", "YG", "G")
    occupied = [tc for tc, v in picture["track_circuits"].items() if v["occupied"]]
    assert summary["occupied"] == sorted(occupied) == ["TC2063"]


def test_a_table_the_ctc_cannot_trust_reads_unknown() -> None:
    rig = StationRig(LINE.view(22), mode=Mode.LOCAL)
    model = CtcModel(LINE).station(22)
    table = table_of(rig, 22)
    table.connected = False  # the link went: the last indications no longer hold
    summary = model.summary(table)
    assert summary["link"] == "down" and not summary["known"]
    assert summary["mode"] == UNKNOWN and summary["routes"] == [] and summary["occupied"] == []
    assert set(summary["points"].values()) == set(summary["signals"].values()) == {UNKNOWN}
    assert model.summary(None)["link"] == "down"
    table.connected, table.synced = True, False  # back, but no full state yet
    assert model.summary(table)["link"] == "up" and not model.summary(table)["known"]


def test_operator_commands_become_the_codes_the_interlocking_reads() -> None:
    ctc = CtcModel(LINE)
    rig = StationRig(LINE.view(18), mode=Mode.CENTER)
    _, controls = link_charts(rig.view, "ixl_to_ctc")

    def act(**command: object) -> tuple[str, int, int]:
        a = ctc.action(command)
        assert a.code == controls.number_of(a.name)
        return a.name, a.value, a.station

    # signals as operators write them: S1, S01 or 01
    route = {"cmd": "route", "station": 18, "entry": "S1", "exit": "S11"}
    assert act(**route, action="set") == ("RSC180111", 1, 18)
    assert act(**route, action="cancel") == ("RCC180111", 1, 18)
    assert act(cmd="point", station="18", point="31", position="reverse") == ("SRC1831", 1, 18)
    assert act(cmd="signal", station=18, signal="S01", action="stop") == ("SSC1801", 1, 18)
    assert act(cmd="signal", station=18, signal="01", action="release") == ("SSC1801", 0, 18)
    assert act(cmd="mode", station=18, mode="center") == ("CMQ18", 1, 18)
    assert act(cmd="control", station=18, code="LMQ18", value=1) == ("LMQ18", 1, 18)
    # a cancel without its exit cancels the route the table reports set from that entry
    with pytest.raises(UsageError, match="no route is set from signal 01"):
        ctc.action({"cmd": "route", "action": "cancel", "station": 18, "entry": "01"})
    assert rig.control("RSC180112").accepted
    ctc.tables.link_up(18, "test")
    ctc.tables.full_state(18, sorted(table_of(rig, 18).state.items()))
    cancel = ctc.action({"cmd": "route", "action": "cancel", "station": 18, "entry": "S1"})
    assert cancel.name == "RCC180112" and cancel.text == "station 18: cancel route 01-12"


@pytest.mark.parametrize(
    ("command", "why"),
    [
        ({"cmd": "point", "station": 99, "point": "31", "position": "reverse"},
         "station 99 is not in this lab (18, 20, 22)"),
        ({"cmd": "route", "station": 18, "entry": "01", "exit": "02"},
         "station 18: no route from signal 01 to 02"),
        ({"cmd": "route", "station": 18, "entry": "01"}, "route command without 'exit'"),
        ({"cmd": "point", "station": 18, "point": "31", "position": "left"},
         "point position must be normal or reverse, not 'left'"),
        ({"cmd": "signal", "station": 18, "signal": "S9"}, "station 18: no signal 09"),
        ({"cmd": "control", "station": 18, "code": "XYZ18"},
         "station 18: no control XYZ18 in the chart"),
        ({"cmd": "control", "station": 18, "code": "CMQ18", "value": "on"},
         "control command: invalid literal"),
        ({"cmd": "fly", "station": 18}, "unknown command 'fly'"),
    ],
)  # fmt: skip
def test_a_command_the_ctc_cannot_carry_out_is_refused_with_the_reason(
    command: dict[str, object], why: str
) -> None:
    with pytest.raises(UsageError) as exc:
        CtcModel(LINE).action(command)
    assert str(exc.value).startswith(why)


def test_the_log_keeps_commands_in_the_operator_words() -> None:
    assert command_words({"cmd": "route", "action": "set", "station": 18, "entry": "S1",
                          "exit": "S11"}) == "route set 18 01 11"  # fmt: skip
    assert command_words({"cmd": "route", "action": "cancel", "station": 18, "entry": "01"}) == (
        "route cancel 18 01"
    )
    assert command_words({"cmd": "signal", "station": 20, "signal": "1"}) == "signal stop 20 01"
    log = CommandLog(keep=2)
    for k in range(3):
        log.record(float(k), {"cmd": "mode", "mode": "center", "station": 18}, "ctc")
    assert [e["time"] for e in log.last(5)] == [1.0, 2.0]
    assert log.last(1)[0]["command"] == "mode center 18"
