"""A down train runs the reference line in the lab in one process (virtual clock): 2001 of
`down_train.yaml` comes on at the east edge (TC2261) and, its routes set by the CTC's ARS, runs
22 -> 20 -> 18 on falling chainage, standing within ±0.5 m of each mark, with no emergency brake
-- on the codes the wayside ATCs give down routes, read by the rails under its head at its lower
chainage end."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from ktcs_bench.datafiles import data_dir
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.train.endpoint import STOP_TOLERANCE

from .conftest import without_trains

TIMETABLE = Path(__file__).with_name("down_train.yaml").resolve()
RUN_S = 1500.0  # 13 km with three stops: about 16 minutes of the lab's clock
MARKS = {"22": 12120.0, "20": 6220.0, "18": 620.0}


def down_lab(tmp: Path) -> Path:
    """The reference lab with only the down train of `down_train.yaml`, ARS on."""
    text = without_trains((data_dir("emulators") / "labs" / "reference.yaml").read_text("utf-8"))
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("lab: reference", "lab: down").replace("port: 8020", "port: 0")
    text = text.replace("line: ../lines/reference.yaml", f"line: {line}")
    text = text.replace("\ntype1:", f"\ntimetable: {TIMETABLE}\nars: {{}}\ntype1:", 1)
    train = '  train2001: {kind: train, train: "2001", host: 127.0.0.1}\n'
    text = text.replace("\nlinks:\n", f"\n{train}links:\n", 1)
    path = tmp / "down.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_down_train_runs_22_20_18_under_ars_stopping_within_half_a_metre(
    tmp_path: Path,
) -> None:
    seen: list[dict[str, Any]] = []  # the train's status every 5 s of the lab's clock

    async def main(lab: InProcessLab) -> dict[str, Any]:
        end = lab.now() + RUN_S
        while lab.now() < end:
            answer = await lab.device("train2001", {"cmd": "status"})
            assert answer["ok"], answer
            seen.append(answer["status"])
            if answer["status"]["state"] == "finished":
                break
            await asyncio.sleep(5.0)
        log = await lab.device("ctc", {"cmd": "log", "last": 1000})
        return {"status": seen[-1], "log": log["log"]}

    out = tmp_path / "run"
    result = InProcessLab(down_lab(tmp_path), out=out).run(main)
    s = result["status"]
    assert s["state"] == "finished" and s["direction"] == "down", s
    assert s["emergency_brakes"] == 0, s
    assert [a["station"] for a in s["arrivals"]] == ["22", "20", "18"], s
    assert [d["station"] for d in s["departures"]] == ["22", "20"], s
    for a in s["arrivals"]:
        assert a["stop_m"] == MARKS[a["station"]], a
        assert abs(a["error_m"]) <= STOP_TOLERANCE, a
        assert abs(a["head_m"] - a["stop_m"]) <= STOP_TOLERANCE, a  # on the true position
    # it ran down: its head (the lower end) falls and leads its tail by the train's length
    # (it comes on 50 m short of TC2261's lower end, 12800 m)
    heads = [x["head"] for x in seen]
    assert heads == sorted(heads, reverse=True), heads
    assert heads[0] == 12850.0 and abs(heads[-1] - MARKS["18"]) <= STOP_TOLERANCE, heads
    assert all(abs(x["tail"] - x["head"] - 200.0) < 1e-6 for x in seen), seen[-1]
    # on the station's main track at each stop (the rails occupy track 1's circuits there)
    assert s["track"] == "1", s
    # what it says of its stops names the chainage too
    events = [json.loads(e) for e in (out / "events.jsonl").read_text().splitlines()]
    said = [e["text"] for e in events if e["device"] == "train2001" and e["kind"] == "arrival"]
    assert [x.split(" m,")[0] for x in said] == [
        f"{a['station']}: front at {a['head_m']:.2f}" for a in s["arrivals"]
    ], said
    # ARS set its routes -- the down home and starting routes of each station -- and nobody else
    log = result["log"]
    assert log and {e["source"] for e in log} == {"ars"}, log
