"""A code carries the direction of travel it is given for (SPEC §6.6): a train running the other
way over the track circuit reads the most restrictive code, not another train's proceed."""

from __future__ import annotations

import pytest

from ktcs_bench.atc.track_circuits import TrackCircuitModel, TrainPosition
from ktcs_bench.atc.track_codes import AtcCode, most_restrictive
from ktcs_bench.atc.wayside import WaysideAtc
from ktcs_bench.emulator.rails import code_from_wire, code_to_wire
from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes import names as n


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


DOWN_80 = AtcCode(4, 80.0, -8.0, 1100.0, "down")


@pytest.mark.parametrize(
    ("head", "tail", "reads_it"), [(2500.0, 2700.0, True), (2700.0, 2500.0, False)]
)
def test_a_train_reads_a_code_only_in_the_direction_it_is_given_for(
    line: Line, head: float, tail: float, reads_it: bool
) -> None:
    model = TrackCircuitModel(line)
    model.update([TrainPosition("T", head, tail)])
    tc = model.under_antenna("T")
    assert tc == "TC1863"
    model.set_codes({tc: DOWN_80})
    code = model.code_for("T")
    if reads_it:  # running down, head at the lower chainage: its own code
        assert code == DOWN_80
    else:  # running up over a code for down trains: stop
        assert code == most_restrictive(line, 8.0)


def test_a_code_for_any_direction_is_read_by_every_train(line: Line) -> None:
    model = TrackCircuitModel(line)
    model.update([TrainPosition("T", 2700.0, 2500.0)])
    stop = most_restrictive(line)
    model.set_codes({"TC1863": stop})
    assert model.code_for("T") == stop and stop.direction is None


def test_the_rails_carry_the_direction_and_take_an_older_four_element_code(line: Line) -> None:
    assert code_to_wire(DOWN_80) == [4, 80.0, -8.0, 1100.0, "down"]
    assert code_from_wire(code_to_wire(DOWN_80)) == DOWN_80
    assert code_from_wire([4, 80, -8, 1100]) == AtcCode(4, 80.0, -8.0, 1100.0, None)
    for bad in ([4, 80, -8, 1100, "sideways"], [4, 80], "4,80,-8,1100", [4, 80, -8, 1100, 1, 2]):
        with pytest.raises((ValueError, TypeError)):
            code_from_wire(bad)


def test_the_wayside_gives_each_code_the_direction_of_its_path(line: Line) -> None:
    atc = WaysideAtc(line, 20)
    atc.link_state(True, 0.0)
    atc.set_occupancy({t.name: False for t in line.all_track_circuits()}, 0.0)
    atc.receive({n.tdu("1820"): 0, n.tdd("1820"): 1}, 0.0)
    assert atc.track_codes()["TC2045"].direction == "down"
    atc.receive({n.tdu("1820"): 1, n.tdd("1820"): 0}, 0.0)
    assert atc.track_codes()["TC2045"].direction == "up"
    atc.receive({n.tdu("1820"): 0, n.tdd("1820"): 0}, 0.0)  # nobody holds: stop, for anyone
    stop = atc.track_codes()["TC2045"]
    assert stop.code == line.most_restrictive_code.code and stop.direction is None
