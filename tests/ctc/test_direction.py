"""Each interval's traffic direction as the CTC reads it from both its stations' indications
(SPEC §6.6): direction, holder, asker, what `ctc show` prints and the log says when it changes;
and `ctc direction ST INTERVAL`, one typed message from the operator's words to the DRC code."""

from __future__ import annotations

import pytest

from ktcs_bench.ctc.log import command_words, parse_words
from ktcs_bench.ctc.model import CtcModel, IntervalWatch
from ktcs_bench.errors import UsageError
from ktcs_bench.messages import CTC, AskDirection, decode, encode
from ktcs_bench.station.loader import load_line
from ktcs_bench.station_codes import names as n

LINE = load_line()


def indicate(model: CtcModel, station: int, **codes: int) -> None:
    """Station `station`'s full state as its IXL would send it: `codes` by name, every other
    indication 0."""
    chart = model.station(station).indications
    state = dict.fromkeys((c.number for c in chart.codes), 0)
    state.update({chart.number_of(k): v for k, v in codes.items()})
    if model.table(station) is None or not model.tables.stations[station].connected:
        model.tables.link_up(station, "test")
    model.tables.full_state(station, list(state.items()))


def holding(iv: str, direction: str, holds: bool = False, asks: bool = False) -> dict[str, int]:
    return {n.tdu(iv): int(direction == "up"), n.tdd(iv): int(direction == "down"),
            n.phi(iv): int(holds), n.prq(iv): int(asks)}  # fmt: skip


def test_the_charts_carry_the_permission_both_ways() -> None:
    model = CtcModel(LINE)
    ind, ctl = model.station(20).indications, model.station(20).controls
    names = [c.name for c in ind.codes]
    older = max(names.index(n.tdd(iv)) for iv in ("1820", "2022"))
    for iv in ("1820", "2022"):
        # after every older code, so that none of theirs is renumbered
        assert names.index(n.phi(iv)) > older
        assert names.index(n.prq(iv)) == names.index(n.phi(iv)) + 1
        last_route = model.station(20).station.routes[-1].name
        assert ctl.number_of(n.drc(iv)) > ctl.number_of(n.rcc(20, last_route))
    # a lab-edge interval has no neighbour to ask
    assert n.drc("1618") not in [c.name for c in model.station(18).controls.codes]


def test_an_interval_is_read_from_both_its_ends() -> None:
    model = CtcModel(LINE)
    iv = model.interval("1820")
    assert iv.known == () and iv.direction is None and iv.holder is None
    assert iv.text == "1820  18 ─── 20  unknown (no indications from either end)"
    indicate(model, 18, **holding("1820", "up", holds=True))
    iv = model.interval("1820")
    assert (iv.direction, iv.holder, iv.asking, iv.known) == ("up", 18, (), (18,))
    assert iv.text == "1820  18 ──▶ 20  (held by 18)"
    indicate(model, 20, **holding("1820", "up", asks=True))
    iv = model.interval("1820")
    assert iv.text == "1820  18 ──▶ 20  (held by 18), asked by 20"
    assert iv.departs_from == 18
    # handed over: 18 gave it up first, 20 not yet holding -- no holder, no direction
    indicate(model, 18, **holding("1820", "none"))
    indicate(model, 20, **holding("1820", "none", asks=True))
    assert model.interval("1820").text == "1820  18 ─── 20  no direction, asked by 20"
    indicate(model, 20, **holding("1820", "down", holds=True))
    indicate(model, 18, **holding("1820", "down"))
    iv = model.interval("1820")
    assert (iv.direction, iv.holder, iv.departs_from) == ("down", 20, 20)
    assert iv.text == "1820  18 ◀── 20  (held by 20)"


def test_faults_between_the_ends_are_shown_not_hidden() -> None:
    model = CtcModel(LINE)
    indicate(model, 18, **holding("1820", "up", holds=True))
    indicate(model, 20, **holding("1820", "down", holds=True))
    iv = model.interval("1820")
    assert iv.direction == "disagree" and iv.holder is None and iv.holders == (18, 20)
    assert "the ends disagree" in iv.text and "held by both 18 and 20" in iv.text
    # a lab-edge interval: its fixed direction's holder is the station outside the lab
    indicate(model, 18, **holding("1618", "up"))
    assert model.interval("1618").text == "1618  16 ──▶ 18  (held by 16, outside the lab)"


def test_show_summary_and_picture_carry_each_interval_of_the_station() -> None:
    model = CtcModel(LINE)
    indicate(model, 20, **holding("1820", "up"), **holding("2022", "up", holds=True))
    indicate(model, 22, **holding("2022", "up", asks=False))
    summary = model.summary(20)
    assert list(summary["intervals"]) == ["1820", "2022"]
    assert summary["intervals"]["2022"] == {
        "interval": "2022", "west": 20, "east": 22, "direction": "up", "holder": 20,
        "asking": [], "text": "2022  20 ──▶ 22  (held by 20)",
    }  # fmt: skip
    assert summary["intervals"]["1820"]["holder"] is None
    assert model.picture(22)["intervals"]["2022"]["holder"] == 20


def test_the_log_says_when_the_permission_changes_hands() -> None:
    model = CtcModel(LINE)
    watch = IntervalWatch()
    indicate(model, 18, **holding("1820", "up", holds=True))
    indicate(model, 20, **holding("1820", "up"))
    assert watch.update(model.intervals()) == []  # the first reading says nothing
    indicate(model, 20, **holding("1820", "up", asks=True))
    assert watch.update(model.intervals()) == ["interval 1820: 20 asks for the permission"]
    indicate(model, 18, **holding("1820", "none"))
    assert watch.update(model.intervals()) == [
        "interval 1820: no end holds the permission (was 18)"
    ]
    indicate(model, 20, **holding("1820", "down", holds=True))
    indicate(model, 18, **holding("1820", "down"))
    assert watch.update(model.intervals()) == [
        "interval 1820: permission to 20",
        "interval 1820: direction down",
    ]
    assert watch.update(model.intervals()) == []


def test_ctc_direction_is_one_typed_message_from_the_words_to_the_drc_code() -> None:
    message = parse_words("direction 20 1820".split())
    assert message == AskDirection(station=20, interval="1820")
    assert command_words(message) == "direction 20 1820"
    assert decode(encode(message), CTC) == message
    assert encode(message) == {"cmd": "direction", "station": 20, "interval": "1820"}
    model = CtcModel(LINE)
    action = model.action(message)
    assert (action.station, action.name, action.value) == (20, "DRC1820", 1)
    assert action.code == model.station(20).controls.number_of("DRC1820")
    assert model.action({"cmd": "direction", "station": 22, "interval": "2022"}).name == ("DRC2022")
    with pytest.raises(UsageError, match="no interval 2022 here"):
        model.action(AskDirection(station=18, interval="2022"))
    with pytest.raises(UsageError, match="lab's edge"):
        model.action(AskDirection(station=18, interval="1618"))
    with pytest.raises(UsageError, match="cannot read"):
        parse_words("direction 20".split())
