"""The live status `lab up` prints: a line per train after the stations."""

from __future__ import annotations

from ktcs_bench.lab.view import station_lines


def test_the_live_status_shows_each_train_its_state_place_speed_and_stops() -> None:
    train = {"kind": "train", "train": "1001", "state": "dwelling", "head": 6779.94,
             "speed_kmh": 0.0, "next_stop": "22",
             "arrivals": [{"station": "18", "error_m": -0.062, "time_s": 65.6},
                          {"station": "20", "error_m": -0.059, "time_s": 402.9}]}  # fmt: skip
    waiting = {"kind": "train", "train": "1003", "state": "waiting", "head": 450.0,
               "speed_kmh": 0.0, "next_stop": "18", "arrivals": []}  # fmt: skip
    status = {"stations": {}, "devices": {"train1001": {"status": train},
                                          "train1003": {"status": waiting},
                                          "ctc": {"status": {"kind": "ctc"}}}}  # fmt: skip
    lines = station_lines(status, colour=False)
    assert lines == [
        "train 1001 dwelling   front   6779.9 m   0.0 km/h  next 22   stops 18:-0.06m@66s 20:-0.06m@403s",
        "train 1003 waiting    front    450.0 m   0.0 km/h  next 18",
    ]
