"""Trains run where the point blades lie, through the real rails (SPEC §6.7): procedures on the
procedures' quiet lab in one process on the virtual clock -- the IXL throws point 31, the
trackside publishes its blades on the rails, and the track-circuit emulator moves the train by
them; a trailed point's detection is lost at the trackside until the run's faults are cleared."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.procedure.steps import Ghost, TrainStep
from tests.lab.conftest import RunningLab, start_lab

LAB = data_dir("emulators") / "procedures" / "labs" / "quiet.yaml"

FACING = f"""
id: facing-point-into-the-loop
title: A train over facing point 31 lying reverse runs into the loop, not onto the main track
setup:
  lab: {LAB}
  trains:
    - {{id: T1, head: 420, length_m: 40}}
steps:
  - ctc: route set 18 01 12
  - expect: ixl 18 point 31 is reverse
    within: 20s
  - expect: ctc 18 signal 01 is Y,YG,G
    within: 15s
  - train: T1 run to 800 at 36
  - expect: ctc 18 tc TC1856 is occupied
    within: 5s
  - expect: ctc 18 tc TC1855 is clear
  - expect: train T1 tc is TC1856
  - expect: no event tc "trailed"
"""

TRAILED = f"""
id: trailed-point-reported
title: A down train leaving the loop over point 31 lying normal trails it
setup:
  lab: {LAB}
steps:
  - ctc: point normal 18 31
  - expect: ixl 18 point 31 is normal
    within: 10s
  - train: T2 place 800 track 2 down
  - expect: ctc 18 tc TC1856 is occupied
    within: 5s
  - train: T2 run to 400 at 30
  - expect: event tc "trailed point 18 31"
  - expect: ixl 18 point 31 is none
    within: 5s
    note: the trailed point has lost its detection
  - expect: ctc 18 tc TC1851 is occupied
  - fault: clear
  - expect: ixl 18 point 31 is reverse
    within: 5s
    note: repaired, detected where the wheels forced the blades
"""

TRAINS = data_dir("emulators") / "procedures" / "labs" / "trains.yaml"

DERAILED = f"""
id: point-moved-under-a-train
title: A wrong-side track-circuit failure lets point 31 move under a train, which derails
setup:
  lab: {TRAINS}
  restart: [train1]
steps:
  - ctc: route set 18 01 11
  - train: T1 run to 620
    note: the train (100 m) stands astride point 31
  - expect: train T1 head > 619
    within: 120s
  - expect: train T1 speed is 0
    within: 30s
  - expect: train T1 tail < 550
  - fault: tc TC1853A failed_clear
    note: the point's track circuit shows clear under the train, so the route releases the point
  - expect: ctc 18 point 31 is normal
    within: 10s
  - ctc: point reverse 18 31
  - expect: event tc "derailed 18 31"
    within: 10s
  - expect: event train1 "derailed at point 18 31"
  - train: T1 run to 1050
    note: a derailed train reads no code, so it never moves again
  - expect: train T1 speed is 0
    holds: 20s
"""

REFERENCE = data_dir("emulators") / "labs" / "reference.yaml"

MISROUTED = f"""
id: timetable-train-misrouted
title: A timetable train booked on the main track sent into the loop says misrouted and stays
setup:
  lab: {REFERENCE}
  ars: false
steps:
  - ctc: route set 18 01 12
    note: 1001 is booked on track 1 at station 18
  - expect: event tc "misrouted"
    within: 180s
  - expect: event train1001 "misrouted onto track 2"
  - expect: train 1001 speed is 0
    within: 120s
  - expect: train 1001 tc is TC1856
  - ctc: route set 18 12 91
  - expect: code TC1856 speed > 0
    within: 15s
  - expect: train 1001 speed is 0
    holds: 30s
    note: held where it stood, though its code lets it go
"""


@pytest.mark.parametrize(
    "text",
    [FACING, TRAILED, DERAILED, MISROUTED],
    ids=["facing", "trailed", "derailed", "misrouted"],
)
def test_a_procedure_train_runs_by_the_blades_through_the_rails(
    tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    proc = tmp_path / "points.yaml"
    proc.write_text(text, encoding="utf-8")
    report = tmp_path / "report"
    code = main(["test", "run", str(proc), "--report", str(report), "--no-colour"])
    out = capsys.readouterr().out
    assert code == 0, out
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    assert [p["verdict"] for p in results["procedures"]] == ["pass"], out


def test_a_placed_train_faces_the_way_the_step_says(tmp_path: Path) -> None:
    head = "id: p\ntitle: t\nsetup: {lab: reference}\nsteps:\n"
    path = tmp_path / "p.yaml"
    path.write_text(head + "  - train: T2 place 6420 track 1 down\n  - train: T3 place 300\n")
    down, default = load_procedure(path).steps
    assert isinstance(down, TrainStep) and isinstance(default, TrainStep)
    assert (down.at, down.track, down.direction) == (6420.0, "1", "down")
    assert default.direction is None  # a new train faces up; placed again, as it faced
    assert Ghost("T2", 6420.0, 40.0, "1", direction="down").tail == 6460.0
    path.write_text(head + "  - train: T2 place 6420 sideways\n")
    with pytest.raises(ConfigError) as err:
        load_procedure(path)
    assert err.value.place == "step 1 (train)" and "up|down" in err.value.problem


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    """The procedures' quiet lab in real processes (as `tests/procedure/test_live.py` has it):
    the trackside processes publish their blades over TCP to the track-circuit process."""
    tmp = tmp_path_factory.mktemp("pointslab")
    text = LAB.read_text(encoding="utf-8")
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("lab: quiet", "lab: pointslab").replace(
        "../../lines/reference.yaml", str(line)
    )
    (tmp / "pointslab.yaml").write_text(text, encoding="utf-8")
    with start_lab(tmp, "pointslab", path=tmp / "pointslab.yaml") as running:
        yield running


def test_the_blades_reach_the_rails_in_a_live_lab(live: RunningLab, tmp_path: Path) -> None:
    """Facing point 31 lying reverse sends the train into the loop, and a down train trails it
    out of the loop, between real processes; the run's fault clear repairs the point."""
    paths = []
    for name, text in (("facing", FACING), ("trailed", TRAILED)):
        paths.append(tmp_path / f"{name}.yaml")
        paths[-1].write_text(text, encoding="utf-8")
    done = live.cli("test", "run", "--live", "pointslab", "--no-colour", "--json",
                    *map(str, paths), timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    verdicts = [p["verdict"] for p in json.loads(done.stdout)["procedures"]]
    assert verdicts == ["pass", "pass"], done.stdout
