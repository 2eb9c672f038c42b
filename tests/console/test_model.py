"""The console's pure parts: diagram layout from station data, the station picture from a CTC
indication table, operator actions to control codes, and the speed–distance provider."""

from __future__ import annotations

import asyncio
import math
import re
from pathlib import Path

import pytest

from ktcs_bench.console.diagram import Scale, build, lane_order
from ktcs_bench.console.trains import EndpointTrains, TrainPosition
from ktcs_bench.ctc.model import CtcModel
from ktcs_bench.errors import UsageError
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.loader import load_line
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import TrainConfig
from tests.console.conftest import make_train

LINE = load_line()
MODELS = CtcModel(LINE).models


def test_every_track_circuit_point_and_signal_is_drawn_once_with_its_id() -> None:
    svg = build(LINE).svg
    for tc in LINE.all_track_circuits():
        assert f'data-tc="{tc.name}"' in svg
    for st in LINE.stations.values():
        for p in st.points:
            assert svg.count(f'id="pt-{st.number}-{p.name}"') == 1
            # every point has a straight and a diverging leg to colour by its position
            assert re.search(rf'data-point="{p.name}" data-leg="reverse"', svg), (st.number, p)
        for s in st.signals:
            assert svg.count(f'id="sig-{st.number}-{s.name}"') == 1
        assert svg.count(f'id="st-{st.number}"') == 1


def test_each_interval_is_drawn_with_an_arrow_over_its_own_stretch_neutral_until_told() -> None:
    """Every interval has one arrow: a shaft and both heads over its stretch of the line, the up
    head to the right (rising chainage); the page keeps one head by the direction it reads."""
    layout = build(LINE)
    assert layout.scale is not None
    for iv in LINE.intervals:
        group = re.search(rf'<g class="interval none" id="iv-{iv.name}"[^>]*>(.*?)</g>', layout.svg)
        assert group is not None, iv.name
        shaft = re.search(r'class="iv-shaft" x1="([\d.]+)" y1="[\d.]+" x2="([\d.]+)"', group[1])
        assert shaft is not None
        x1, x2 = float(shaft[1]), float(shaft[2])
        assert layout.scale.x(iv.from_m) <= x1 < x2 <= layout.scale.x(iv.to_m)
        up = re.search(r'class="iv-head up" points="([\d.]+),', group[1])
        down = re.search(r'class="iv-head down" points="([\d.]+),', group[1])
        assert up is not None and down is not None
        assert float(down[1]) < x1 < x2 < float(up[1])  # each head beyond its end of the shaft


def test_lanes_keep_a_siding_beyond_the_track_it_branches_from() -> None:
    assert lane_order(LINE.station(18)) == {"1": 0, "2": 1}
    assert lane_order(LINE.station(20)) == {"1": 0, "2": 1, "3": -1}  # 3 branches off the main
    assert lane_order(LINE.station(22)) == {"1": 0, "2": 1, "3": 2}  # siding 3 off track 2


def test_the_scale_runs_left_to_right_through_every_boundary() -> None:
    scale = Scale(LINE)
    xs = [scale.x(b) for b in scale.breaks]
    assert all(b > a for a, b in zip(xs, xs[1:], strict=False))
    assert scale.x(LINE.start_m) < scale.x(6500) < scale.x(LINE.end_m) < scale.width


def _picture(rig: StationRig, number: int = 18) -> dict[str, object]:
    model = MODELS[number]
    chart, _ = link_charts(rig.view, "ixl_to_ctc")  # the numbers the interlocking's link sends
    table = {chart.number_of(k): v for k, v in rig.ctc.items()}
    return model.picture(table, True, True)


def test_picture_of_a_set_route_locks_its_track_circuits_and_clears_its_signal() -> None:
    rig = StationRig(LINE.view(18), mode=Mode.CENTER)
    before = _picture(rig)
    assert before["mode"] == "center"
    assert before["signals"]["01"]["aspect"] == "R"  # type: ignore[index]
    assert rig.control("RSC180111").accepted
    pic = _picture(rig)
    tcs = pic["track_circuits"]
    assert tcs["TC1855"] == {"occupied": False, "locked": True}  # type: ignore[index]
    assert tcs["TC1857A"]["locked"]  # overlap  # type: ignore[index]
    assert not tcs["TC1856"]["locked"]  # type: ignore[index]
    assert pic["signals"]["01"]["aspect"] in ("Y", "YG", "G")  # type: ignore[index]
    assert pic["points"]["31"] == {"position": "normal", "moving": False, "locked": True}  # type: ignore[index]
    assert pic["routes"]["0111"]["set"]  # type: ignore[index]
    rig.occupy("TC1851")
    assert _picture(rig)["track_circuits"]["TC1851"]["occupied"]  # type: ignore[index]


def test_picture_of_a_moving_point_and_of_an_unknown_table() -> None:
    rig = StationRig(LINE.view(20), mode=Mode.CENTER)
    assert rig.control("SRC2033").accepted
    rig.advance(0.5)
    assert _picture(rig, 20)["points"]["33"]["position"] == "to_reverse"  # type: ignore[index]
    rig.advance(5.0)
    assert _picture(rig, 20)["points"]["33"]["position"] == "reverse"  # type: ignore[index]
    model = MODELS[20]
    empty = model.picture({}, False, False)
    assert empty["mode"] == "unknown" and empty["connected"] is False
    assert empty["track_circuits"]["TC2055"]["occupied"] is None  # type: ignore[index]


def test_actions_map_to_the_control_chart() -> None:
    model = MODELS[18]
    indications, controls = link_charts(LINE.view(18), "ixl_to_ctc")  # as the IXL's link numbers
    act = model.set_route("01", "12")
    assert (act.name, act.code, act.value) == ("RSC180112", controls.number_of("RSC180112"), 1)
    assert model.move_point("32", "reverse").name == "SRC1832"
    assert model.mode("center").name == "CMQ18"
    assert model.mode("local").name == "LMQ18"
    rsi = indications.number_of("RSI180112")
    assert model.cancel_route("01", {rsi: 1}).name == "RCC180112"
    with pytest.raises(UsageError, match="no route is set from signal 01"):
        model.cancel_route("01", {rsi: 0})
    with pytest.raises(UsageError, match="no route from signal 01 to 02"):
        model.set_route("01", "02")
    with pytest.raises(UsageError, match="no point 99"):
        model.move_point("99", "normal")


def test_speed_distance_provider_gives_ordered_curves_around_the_train() -> None:
    ep = make_train()
    source = EndpointTrains({"T1": ep})
    assert source.train_ids() == ["T1"]
    assert asyncio.run(source.speed_distance("T2")) is None
    sd = asyncio.run(source.speed_distance("T1"))
    assert sd is not None
    assert sd.x[0] <= sd.front_m <= sd.x[-1]
    assert math.isclose(sd.speed_kmh, ep.state.speed * 3.6, abs_tol=0.01)
    assert sd.target_m == 2500.0
    c = sd.curves
    for i in range(len(sd.x)):
        ebi, sbi, perm, mrsp = c["ebi"][i], c["sbi"][i], c["permitted"][i], c["mrsp"][i]
        assert ebi is not None and sbi is not None and perm is not None and mrsp is not None
        assert ebi >= sbi >= perm and perm <= mrsp
    # the stop target at 2500 m brings the permitted speed to 0 before it
    at_target = [p for x, p in zip(sd.x, c["permitted"], strict=True) if x >= 2500.0]
    assert at_target and all(p == 0.0 for p in at_target)


def test_train_places_come_from_each_train_process_over_its_control_port(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The CTC's `RemoteTrains` (the trains the lab registered with `add_train`) asks each
    train process's control port for its status over TCP: a train on the line is placed on the
    diagram by its front, rear and track; one not on the line yet, or not answering, is not."""
    from ktcs_bench.emulator.ctc import RemoteTrains
    from ktcs_bench.emulator.train import TrainDevice
    from ktcs_bench.runtime import TOKEN_ENV, server_token
    from ktcs_bench.transport.endpoints import parse_endpoint

    line = load_line()
    token, file = server_token(tmp_path / "token")  # the lab's token: the devices require it
    monkeypatch.setenv(TOKEN_ENV, str(file))

    async def run() -> list[TrainPosition]:
        devices = {}
        source = RemoteTrains()
        for train, start in (("T1", 420.0), ("T2", 2500.0), ("T3", 4000.0)):
            cfg = TrainConfig(train, TrainParams(length=100.0), start=start, mode="ktcs", ato=True)
            dev = devices[train] = TrainDevice(
                train, line, cfg, parse_endpoint("tcp://127.0.0.1:9")
            )
            dev.token = token
            await dev.start()
            host, _, port = dev.ready_info["control"].rpartition(":")
            source.add(train, host, int(port))
            dev.endpoint.handle_timer(0.1)  # its first cycle: it is on the line
        devices["T2"].endpoint.cycles = 0  # T2 has not come onto the line yet (waiting)
        await devices["T3"].close()  # T3's process is gone: its port answers no more
        try:
            return await source.positions()
        finally:
            for dev in devices.values():
                await dev.close()

    (t1,) = asyncio.run(run())
    assert (t1.train, t1.head_m, t1.tail_m, t1.speed_kmh, t1.state) == ("T1", 420.0, 320.0, 0.0,
                                                                         "held")  # fmt: skip
    layout = build(line)
    place = layout.place(t1.head_m, t1.tail_m, t1.track)
    assert place.head_x == layout.scale.x(420.0) > place.tail_x and place.y == layout.y0
