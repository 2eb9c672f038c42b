"""Safety of the integrated system, proven by search (issue 15 part 3, issue 23, SPEC §11).

A hypothesis state machine over the whole lab in one process on the virtual clock
(`InProcessLab`: the CTC, three IXLs linked to their neighbours, ATCs and tracksides, the track
circuits and four trains running the `safety` timetable both ways -- emulators/labs/safety.yaml).
Its rules are what an operator and the world do to the lab: CTC route set and cancel (any route
of any station), `ctc direction` asks, point and signal commands (points thrown under trains
too), mode changes, the trains' drivers releasing an emergency brake, and faults -- any link (the
IXL-IXL ones too) cut and restored, bit-error bursts, garbage and dropped frames, point detection
lost or crossed (wrong-side), a track circuit failed occupied, an IXL or ATC restarted. Every
step lets the lab run a few seconds of its clock, looked at every second: invariants 1-3, 5 and 6
of `lab.invariants` / `lab.intervals` after every look (trains apart, no head past a danger
point, no point moving under a train or a locked route, none run onto lying wrong or through a
point not lying for it, no trailed point, no derailment; no departures into one interval from
both ends, no train entering an interval against another or a locked departure); a settle step
clears every fault and waits until each CTC view equals its IXL and each IXL's occupancy the
rails (invariant 4).

What the search exercised (routes set, released and cancelled, points thrown each way, aspects
shown, faults injected: operation coverage, `evidence.coverage`, from the labs' events as they
come) is written after the run to `coverage.json` in KTCS_SYSTEM_FAILURES, or to the file
KTCS_SYSTEM_COVERAGE names, for `ktcs-bench trace` to merge.

A failure shrinks, and the shrunk sequence is saved as a replay file (seed + steps, in
KTCS_SYSTEM_FAILURES, default `.system-safety/` in the repository) named in the failure message;
`ktcs-bench lab simulate --replay FILE` runs it again. KTCS_SYSTEM_STEPS raises the number of steps
(default 2,000 a run). Two narrower searches show the search can fail: with the direction check
switched off it finds a head-on, with trains moved along their booked track a train through a
point not lying for it (test-only switches, docs/system_safety.md).
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import subprocess
import sys
from collections.abc import Coroutine
from pathlib import Path
from typing import Any, TypeVar

import pytest
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    precondition,
    rule,
    run_state_machine_as_test,
)

from ktcs_bench.atc.track_circuits import TrackCircuitModel
from ktcs_bench.datafiles import data_dir
from ktcs_bench.evidence.coverage import (
    COVERAGE_FILE,
    OperationCoverage,
    lab_events_coverage,
    write_coverage,
)
from ktcs_bench.ixl.interlocking import Interlocking
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.lab.invariants import Geometry, SafetyChecker
from ktcs_bench.lab.safety import Replay, StepRun, load_replay, replay_steps, run_step, run_steps
from ktcs_bench.lab.topology import load_lab
from ktcs_bench.station import load_line
from ktcs_bench.transport import memory

T = TypeVar("T")
ROOT = Path(__file__).resolve().parents[2]
LAB = data_dir("emulators") / "labs" / "safety.yaml"
LAB_NAME = "safety"  # what a replay file names: the shipped lab, wherever the checkout is
LINE = load_line()
GEO = Geometry(LINE)
FAILURES = Path(os.environ.get("KTCS_SYSTEM_FAILURES", ROOT / ".system-safety"))
COVERAGE = Path(os.environ.get("KTCS_SYSTEM_COVERAGE", FAILURES / COVERAGE_FILE))
STEPS = int(os.environ.get("KTCS_SYSTEM_STEPS", "2000"))
STEPS_PER_EXAMPLE = 200
WARM_UP_S = 8.0  # the links come up, the CTC has every station
RUN_S = (0.5, 1.0, 2.0, 4.0)
COUNT = {"steps": 0, "looks": 0, "examples": 0}
SEEDS: list[int] = []  # the lab seeds drawn, printed at the end (pytest -s shows them)

# Traffic both ways (SPEC §6.6, §6.7): three trains run up on the main track and 2002 down on the
# loops, moved by the blades as they lie; the operator sets any route of any station, asks for
# an interval's permission, throws points under trains and injects wrong-side point faults.
ROUTES = [(st.number, r.name, r.entry, r.exit) for st in LINE.stations.values() for r in st.routes]
INTERVALS = [
    (n, iv.name) for n in LINE.stations for iv in LINE.view(n).intervals if not iv.boundary
]
TRAINS = ["train2001", "train2002", "train2003", "train2005"]
POINTS = [(st.number, p.name) for st in LINE.stations.values() for p in st.points]
SIGNALS = [(st.number, s.name) for st in LINE.stations.values() for s in st.lamp_signals]
TCS = [t.name for t in LINE.all_track_circuits()]
STATIONS = sorted(LINE.stations)


class SearchMachine(RuleBasedStateMachine):
    """The lab under search, with no rules of its own: `SystemMachine` is the whole search,
    `DepartureMachine` the narrower operator of the can-fail demonstrations."""

    FAIL_ON: frozenset[str] | None = None  # violation kinds that fail it (None: every one)
    SAVE = True  # a failure is saved as a replay file
    exercised: OperationCoverage | None = None  # what the search did (None: not recorded)

    def __init__(self) -> None:
        super().__init__()
        self.lab: InProcessLab | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self.steps: list[dict[str, Any]] = []
        self.checker = SafetyChecker(LINE)

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        assert self.loop is not None
        return self.loop.run_until_complete(coro)

    @initialize(seed=st.integers(0, 2**16))
    def up(self, seed: int) -> None:
        COUNT["examples"] += 1
        SEEDS.append(seed)
        self.seed = seed
        cov = self.exercised
        on_event = None if cov is None else (lambda e: cov.event(e["device"], e["kind"], e["text"]))
        self.lab = InProcessLab(LAB, seed=seed, on_event=on_event)
        self.loop = self.lab.new_loop()
        self.run(self.lab.up())
        self.run(self.lab.sleep(WARM_UP_S))
        self.run(run_steps(self.lab, self.checker, []))

    def teardown(self) -> None:
        if self.lab is not None and self.loop is not None:
            self.run(self.lab.down())
            memory.detach(self.loop)
            self.loop.close()

    def step(self, step: dict[str, Any]) -> None:
        assert self.lab is not None
        self.steps.append(step)
        COUNT["steps"] += 1
        if self.exercised is not None:  # the lab logs its tap faults and restarts itself
            if step["do"] == "point_fault":
                kind = step.get("kind", "detection")
                self.exercised.fault(f"point {step['station']} {step['point']} {kind}")
            elif step["do"] == "tc_fault":
                self.exercised.fault(f"tc {step['tc']} {step.get('kind', 'failed_occupied')}")
        looks = self.checker.looks
        done = self.run(run_step(self.lab, self.checker, step))
        COUNT["looks"] += self.checker.looks - looks
        found = [v for v in done.violations if self.FAIL_ON is None or v.kind in self.FAIL_ON]
        if found:
            self.fail([str(v) for v in found])

    def fail(self, violations: list[str]) -> None:
        if not self.SAVE:
            raise AssertionError(f"after {len(self.steps)} steps: {violations[0]}")
        replay = Replay(LAB_NAME, self.seed, WARM_UP_S, tuple(self.steps), tuple(violations))
        text = json.dumps(replay.to_json(), sort_keys=True)
        path = FAILURES / f"replay-{hashlib.sha256(text.encode()).hexdigest()[:12]}.json"
        replay.write(path)
        raise AssertionError(
            f"{len(violations)} violation(s), the first: {violations[0]}\n"
            f"replay: ktcs-bench lab simulate --replay {path}"
        )


class SystemMachine(SearchMachine):
    # ---------------------------------------------------------------- the operator

    @rule(route=st.sampled_from(ROUTES), cancel=st.booleans(), run_s=st.sampled_from(RUN_S))
    def route(self, route: tuple[int, str, str, str], cancel: bool, run_s: float) -> None:
        number, _, entry, exit_ = route
        action = "cancel" if cancel else "set"
        self.step({"do": "route", "station": number, "entry": entry, "exit": exit_,
                   "action": action, "run_s": run_s})  # fmt: skip

    @rule(station=st.sampled_from(STATIONS), down=st.booleans(), run_s=st.sampled_from(RUN_S))
    def routes_for_the_trains(self, station: int, down: bool, run_s: float) -> None:
        """The common case, as ARS would: home and starting route of the main track set (up),
        or of the loop (down)."""
        for entry, exit_ in (("02", "22"), ("22", "92")) if down else (("01", "11"), ("11", "91")):
            self.step({"do": "route", "station": station, "entry": entry, "exit": exit_,
                       "action": "set", "run_s": 0.0})  # fmt: skip
        self.step({"do": "wait", "run_s": run_s})

    @rule(interval=st.sampled_from(INTERVALS), run_s=st.sampled_from(RUN_S))
    def direction(self, interval: tuple[int, str], run_s: float) -> None:
        """`ctc direction ST IV`: ask for the interval's permission ahead of a departure."""
        self.step({"do": "direction", "station": interval[0], "interval": interval[1],
                   "run_s": run_s})  # fmt: skip

    @rule(station=st.sampled_from(STATIONS), on=st.booleans(), run_s=st.sampled_from(RUN_S))
    def ars(self, station: int, on: bool, run_s: float) -> None:
        self.step({"do": "ars", "station": station, "on": on, "run_s": run_s})

    @rule(point=st.sampled_from(POINTS), reverse=st.booleans(), run_s=st.sampled_from(RUN_S))
    def point(self, point: tuple[int, str], reverse: bool, run_s: float) -> None:
        position = "reverse" if reverse else "normal"
        self.step({"do": "point", "station": point[0], "point": point[1], "position": position,
                   "run_s": run_s})  # fmt: skip

    @rule(signal=st.sampled_from(SIGNALS), stop=st.booleans(), run_s=st.sampled_from(RUN_S))
    def signal(self, signal: tuple[int, str], stop: bool, run_s: float) -> None:
        self.step({"do": "signal", "station": signal[0], "signal": signal[1],
                   "action": "stop" if stop else "release", "run_s": run_s})  # fmt: skip

    @rule(station=st.sampled_from(STATIONS), local=st.booleans(), run_s=st.sampled_from(RUN_S))
    def mode(self, station: int, local: bool, run_s: float) -> None:
        self.step({"do": "mode", "station": station, "mode": "local" if local else "center",
                   "run_s": run_s})  # fmt: skip

    # ---------------------------------------------------------------- the trains and time

    @rule(train=st.sampled_from(TRAINS),
          run_s=st.sampled_from(RUN_S))  # fmt: skip
    def release_eb(self, train: str, run_s: float) -> None:
        self.step({"do": "release_eb", "train": train, "run_s": run_s})

    @rule(run_s=st.sampled_from((5.0, 10.0, 20.0)))
    def wait(self, run_s: float) -> None:
        self.step({"do": "wait", "run_s": run_s})

    # ---------------------------------------------------------------- faults

    @rule(data=st.data(), run_s=st.sampled_from(RUN_S))
    def link_fault(self, data: st.DataObject, run_s: float) -> None:
        assert self.lab is not None
        link = data.draw(st.sampled_from(sorted(self.lab.links)))
        fault = data.draw(
            st.sampled_from(
                [
                    {"cmd": "cut"},
                    {"cmd": "restore"},
                    {"cmd": "ber", "rate": 1e-3},
                    {"cmd": "ber", "rate": 1e-2},
                    {"cmd": "garbage", "hex": "02ff0010"},
                    {"cmd": "drop-frame", "count": 1},
                    {"cmd": "drop-frame", "count": 3},
                    {"cmd": "clear"},
                ]  # fmt: skip
            )
        )
        self.step({"do": "link", "link": link, "fault": fault, "run_s": run_s})

    @rule(point=st.sampled_from(POINTS), kind=st.sampled_from(["detection", "crossed"]),
          run_s=st.sampled_from(RUN_S))  # fmt: skip
    def point_fault(self, point: tuple[int, str], kind: str, run_s: float) -> None:
        """Detection lost, or crossed: blades lying one way reported the other (wrong-side)."""
        self.step({"do": "point_fault", "station": point[0], "point": point[1], "kind": kind,
                   "run_s": run_s})  # fmt: skip

    @rule(tc=st.sampled_from(TCS), run_s=st.sampled_from(RUN_S))
    def track_circuit_failed_occupied(self, tc: str, run_s: float) -> None:
        self.step({"do": "tc_fault", "tc": tc, "run_s": run_s})

    # IXLs and ATCs: an IXL restarted while holding an interval's permission is not read by its
    # neighbour as giving it (`test_a_restarted_holder_is_not_read_as_a_gift`), nor does one
    # restarted throw a point whose detection lies under a train
    # (`test_a_restarted_ixl_no_longer_throws_a_point_detected_wrong_under_a_train`)
    @rule(device=st.sampled_from([f"{k}{n}" for k in ("ixl", "atc") for n in STATIONS]),
          run_s=st.sampled_from(RUN_S))  # fmt: skip
    def restart(self, device: str, run_s: float) -> None:
        self.step({"do": "restart", "device": device, "run_s": run_s})

    @precondition(lambda self: len(self.steps) > 0)
    @rule()
    def settle(self) -> None:
        """Every fault cleared, the line left to settle: then the views must agree."""
        self.step({"do": "settle", "run_s": 10.0})


@pytest.mark.requirement("SYS-SAFE-01", "SYS-SAFE-02", "SYS-SAFE-03", "SYS-VIEW-01",
                         "IXL-INV-05", "IXL-INV-06")  # fmt: skip
def test_the_integrated_system_stays_safe_under_random_commands_trains_and_faults() -> None:
    COUNT.update(steps=0, looks=0, examples=0)
    SEEDS.clear()
    SystemMachine.exercised = exercised = lab_events_coverage(load_lab(LAB))
    try:
        while COUNT["steps"] < STEPS:  # an example may end before its last step: run on to STEPS
            run_state_machine_as_test(
                SystemMachine,
                settings=settings(
                    max_examples=max(1, -(-(STEPS - COUNT["steps"]) // STEPS_PER_EXAMPLE)),
                    stateful_step_count=STEPS_PER_EXAMPLE,
                    deadline=None,
                    suppress_health_check=list(HealthCheck),
                ),
            )
    finally:  # what the search exercised, failed or not (a shrinking run's examples too)
        SystemMachine.exercised = None
        write_coverage(COVERAGE, exercised)
    print(f"{COUNT['steps']} steps clean, lab seeds {SEEDS}; exercised: {COVERAGE}")
    # the lab was looked at through every step's run, not only stepped
    assert COUNT["looks"] >= COUNT["steps"], COUNT


def test_the_search_records_what_it_exercised_for_trace(tmp_path: Path) -> None:
    """The search's lab as a search example brings it up, stepped by hand: what the steps
    exercised -- the tap's fault (not its clearing), a point and a track-circuit fault, a restart,
    a route set and the points it threw -- is counted from the lab's events and the steps, and
    `ktcs-bench trace` reads the written file as operation coverage."""
    machine = SystemMachine()
    machine.exercised = cov = lab_events_coverage(load_lab(LAB))
    try:
        machine.up(seed=1)
        machine.route((18, "0112", "01", "12"), cancel=False, run_s=10.0)  # into the loop
        for step in (
            {"do": "link", "link": "st20-atc", "fault": {"cmd": "cut"}, "run_s": 1.0},
            {"do": "link", "link": "st20-atc", "fault": {"cmd": "clear"}, "run_s": 1.0},
        ):
            machine.step(step)
        machine.point_fault((22, "31"), "crossed", run_s=1.0)
        machine.track_circuit_failed_occupied("TC2055", run_s=1.0)
        machine.restart("ixl22", run_s=1.0)
    finally:
        machine.teardown()
    doc = json.loads(write_coverage(tmp_path / "coverage.json", cov).read_text(encoding="utf-8"))
    assert doc["observed"] == ["aspects", "faults", "points", "routes"]  # no codes in the events
    st = doc["stations"]
    assert st["18"]["routes"]["0112"]["set"] == 1 and st["18"]["points"]["31"]["reverse"] == 1
    assert st["18"]["aspects"]["01"]["R"] >= 1  # as every signal starts
    assert st["20"]["faults"]["link cut"] == 1 and "link clear" not in st["20"]["faults"]
    assert st["22"]["faults"]["point crossed"] == 1 and st["20"]["faults"]["tc failed_occupied"]
    assert st["22"]["faults"]["restart ixl"] == 1
    out = tmp_path / "trace"
    run = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "trace",
                          str(tmp_path / "coverage.json"), "--out", str(out), "--json"],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stderr
    never = json.loads(run.stdout)["operations"]
    assert "0112" not in never["routes_never_set"]["18"] and "codes_never_sent" not in never
    assert "link cut" not in never["faults_never_injected"]["20"]


# A wrong-side failure (a track circuit failing clear under the train standing at station 18's
# platform -- not among the search's faults) lets the interlocking set the home route into that
# platform, and the train behind runs in on the standing one.
FAILS_CLEAR = Replay(
    LAB_NAME,
    seed=1,
    warm_up_s=WARM_UP_S,
    steps=(
        {"do": "tc_fault", "tc": "TC1855", "kind": "failed_clear", "run_s": 1.0},
        {"do": "route", "station": 18, "entry": "01", "exit": "11", "action": "set"}
        | {"run_s": 120.0},
    ),
)


def test_the_checks_see_a_train_run_into_another_when_a_track_circuit_fails_clear() -> None:
    """The search can fail: run as a replay file is, FAILS_CLEAR gives the violations of
    invariants 1 and 2."""
    lab = InProcessLab(LAB, seed=FAILS_CLEAR.seed)
    runs = lab.run(lambda access: replay_steps(access, FAILS_CLEAR, LINE))
    assert runs[1].answer["ok"], runs[1].answer
    found = {(v.invariant, v.kind) for r in runs for v in r.violations}
    assert (1, "shared_track_circuit") in found and (2, "train_rear") in found, found


def test_lab_simulate_replays_a_saved_failure(tmp_path: Path) -> None:
    """`ktcs-bench lab simulate --replay FILE` (a real process) runs the file's lab, seed and
    steps with the search's checks, prints each violation with its step and exits 1; a broken
    file is a usage error naming it (exit 2)."""
    path = FAILS_CLEAR.write(tmp_path / "replay.json")
    run = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "simulate",
                          "--replay", str(path)], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 1, run.stdout + run.stderr
    assert "invariant 1 (shared_track_circuit) at TC1855" in run.stdout, run.stdout
    assert f"replay {path}: lab safety, seed 1, 2 steps" in run.stdout, run.stdout
    (tmp_path / "bad.json").write_text('{"lab": "safety", "steps": [{"do": "fly"}]}')
    run = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "simulate",
                          "--replay", str(tmp_path / "bad.json")], capture_output=True, text=True,
                         timeout=60)  # fmt: skip
    assert run.returncode == 2 and "bad.json" in run.stderr and "Traceback" not in run.stderr


def test_an_ixl_restarted_under_a_departing_train_keeps_what_it_may_run_onto_locked() -> None:
    """What the search found (docs/system_safety.md): train 2003 leaves station 18's platform on
    routes 01-11 and 11-91; its IXL crashes and restarts as the train runs past starting signal
    11. The new IXL knew nothing of the routes: the train's head ran into TC1857A (point 32) held
    by no route. Restarted in a running lab, an IXL now starts with start-up locking, and the
    checks see the train run on through locked ground."""
    set_1191 = {"do": "route", "station": 18, "entry": "11", "exit": "91", "action": "set"}
    steps = (
        {"do": "ars", "station": 18, "on": False, "run_s": 0.0},
        {**set_1191, "run_s": 17.5},  # the train leaves at 20 s: it is at the signal at 25.5 s
        {"do": "restart", "device": "ixl18", "run_s": 30.0},
    )
    replay = Replay(LAB_NAME, seed=1, warm_up_s=WARM_UP_S, steps=steps)
    lab = InProcessLab(LAB, seed=replay.seed)

    async def run(access: InProcessLab) -> tuple[list[StepRun], dict[str, Any], float]:
        runs = await replay_steps(access, replay, LINE)
        ixl = (await access.device("ixl18", {"cmd": "status"}))["status"]
        train = (await access.device("train2003", {"cmd": "status"}))["status"]
        return runs, ixl, float(train["head"])

    runs, ixl18, head = lab.run(run)
    assert all(r.answer["ok"] for r in runs), [r.answer for r in runs]
    assert [str(v) for r in runs for v in r.violations] == []
    assert head > 1200, "the train ran on past the signal and through the station"
    assert ixl18["startup_held"], "the restarted IXL still holds its station"


def replayed_violations(saved: str) -> list[str]:
    """The violations a run saved in `replays/` shows when replayed on a fresh lab, its seed."""
    replay = load_replay(Path(__file__).parent / "replays" / saved)
    lab = InProcessLab(LAB, seed=replay.seed)
    runs = lab.run(lambda access: replay_steps(access, replay, LINE))
    return [str(v) for r in runs for v in r.violations]


def test_a_down_departure_no_longer_codes_the_up_train_standing_on_its_approach() -> None:
    """What the search found (seed 16080, 163 steps, replayed as it was saved): up train 2005
    stood on station 18's track 1; the operator set the down departure 21-92 from it; the train
    departed on that route's code and ran past starting signal 11 at stop into TC1857A. A code
    now carries its direction (SPEC §6.6): the up train reads the down route's code as the most
    restrictive, and stays behind signal 11."""
    assert replayed_violations("opposing_departure_from_an_occupied_track.json") == []


def test_a_restarted_holder_is_not_read_as_a_gift() -> None:
    """What the search found (seed 40000, 51 steps; cut by hand to its 3 steps that matter):
    train 2002 ran down into interval 2022 from station 22, which held its permission; ixl22
    restarted, and came back before ixl20 saw the link go into communication error. The new ixl22 knows no
    permission and resyncs saying PHI 0; ixl20 had last read PHI 1, and reads any PHI 1 -> 0 on
    a live link as a gift (`IntervalEnd.receive`): it took the permission, locked departure
    11-91 and sent train 2001 up into the interval against 2002 (invariant 6). A PHI 1 -> 0 is
    now a gift only as the answer to an ask, with the giver's departure and half clear; any
    other is a neighbour that forgot, read again as a resync, and nobody holds the permission
    until the interval is clear."""
    assert replayed_violations("a_restarted_holder_read_as_a_gift.json") == []


@pytest.mark.parametrize(
    "saved",
    [
        "point_thrown_under_a_train_after_ixl_restarts.json",  # as the search saved it
        "a_point_detected_wrong_thrown_under_a_train_by_a_restarted_ixl.json",  # cut by hand
    ],
)
def test_a_restarted_ixl_no_longer_throws_a_point_detected_wrong_under_a_train(saved: str) -> None:
    """What the search found once IXL restarts were back in it (seed 535, 203 steps; cut by hand
    to the 3 that matter): train 2003 departs from station 18 on route 11-91 and is in TC1857A
    when point 32's detection is crossed (a wrong-side fault: the blades lying normal reported
    reverse); ixl18 restarts. The new IXL took the position it read for its demand, reverse,
    and the point machine threw the blades under the train, which derailed (invariant 3).
    Restarted, an IXL now demands no point until a route or a control does, with their checks."""
    assert replayed_violations(saved) == []


@pytest.mark.parametrize(
    "saved",
    [
        "a_point_called_where_a_crossed_detection_read_it.json",  # as the search saved it
        "a_point_called_where_a_crossed_detection_read_it_cut.json",  # cut by hand
    ],
)
def test_a_called_point_is_not_proven_by_what_was_read_before_its_call(saved: str) -> None:
    """What the search found with IXL restarts back in it (seed 1244, 188 steps; cut by hand to
    5, no restart needed): point 32 of station 18 lay normal with its detection crossed
    (reported reverse). Route 02-22 called it reverse, and route 22-92 was asked in the same
    instant, before the trackside had answered the call: the IXL took the reverse it had read
    before its call as proof, set 02-22 and cleared signal 02 -- then the blades moved under the
    set route (invariant 3, `point_moved_locked`). The trackside now answers every call with the
    point's indications, and the IXL believes a detection only once its call is answered."""
    assert replayed_violations(saved) == []


# ------------------------------------------------------------------------ the search can fail

DEPARTURES = [r for r in ROUTES if r[3] in ("91", "92")]


class NarrowSearch(SearchMachine):
    """The search's operator narrowed to setting routes (each machine says which) and waiting,
    for the searches shown able to fail."""

    SAVE = False

    def set_route(self, route: tuple[int, str, str, str], run_s: float) -> None:
        number, _, entry, exit_ = route
        self.step({"do": "route", "station": number, "entry": entry, "exit": exit_,
                   "action": "set", "run_s": run_s})  # fmt: skip

    @rule(run_s=st.sampled_from((5.0, 10.0, 20.0)))
    def wait(self, run_s: float) -> None:
        self.step({"do": "wait", "run_s": run_s})


class DepartureMachine(NarrowSearch):
    """The search's operator narrowed to departure routes and waits (ARS on, the trains running
    their timetable): with the IXLs' direction check switched off, a departure against the
    interval's permission is locked and the search must see a head-on."""

    FAIL_ON = frozenset({"opposing_trains", "entered_against_departure"})  # invariant 6
    SAVE = False

    @rule(route=st.sampled_from(DEPARTURES), run_s=st.sampled_from(RUN_S))
    def departure(self, route: tuple[int, str, str, str], run_s: float) -> None:
        self.set_route(route, run_s)


def _search_fails(machine: type[SearchMachine], steps: int, per_example: int = 40) -> str:
    """Run `machine` as the search runs, derandomized (a fixed seed), no shrinking: the
    failure's message (the test fails when the search finds nothing)."""
    COUNT.update(steps=0, looks=0, examples=0)
    try:
        run_state_machine_as_test(
            machine,
            settings=settings(
                max_examples=max(1, steps // per_example),
                stateful_step_count=per_example,
                deadline=None,
                derandomize=True,
                database=None,
                phases=[Phase.generate],
                suppress_health_check=list(HealthCheck),
            ),  # fmt: skip
        )
    except AssertionError as exc:
        print(f"{machine.__name__}: {COUNT['steps']} steps, {COUNT['examples']} examples: {exc}")
        return str(exc)
    raise AssertionError(f"the search found nothing in {COUNT['steps']} steps")


@pytest.mark.requirement("IXL-INV-06")
def test_the_search_finds_a_head_on_when_the_direction_check_is_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With `Interlocking.direction_check_disabled_for_tests` set (the IXL before SPEC §6.6) the
    search sees two trains meet in one interval (invariant 6) within a few steps."""
    monkeypatch.setattr(Interlocking, "direction_check_disabled_for_tests", True)
    found = _search_fails(DepartureMachine, 200)
    assert "invariant 6" in found, found
    assert COUNT["steps"] <= 200, COUNT


class RouteMachine(NarrowSearch):
    """The search's operator narrowed to setting any route and waiting (ARS on): with trains
    moved along their booked track instead of by the blades, a route into a loop sends a train
    booked on the main track through the point lying for the loop, and the search must see it."""

    FAIL_ON = frozenset({"through_point_not_lying"})  # invariant 3
    SAVE = False

    @rule(route=st.sampled_from(ROUTES), run_s=st.sampled_from(RUN_S))
    def route(self, route: tuple[int, str, str, str], run_s: float) -> None:
        self.set_route(route, run_s)


def test_the_search_finds_a_train_through_a_point_not_lying_for_it_when_trains_ignore_the_blades(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With `TrackCircuitModel.booked_tracks_for_tests` set (the rails before SPEC §6.7) the
    search sees a train run through a point that does not lie for it (invariant 3)."""
    monkeypatch.setattr(TrackCircuitModel, "booked_tracks_for_tests", True)
    found = _search_fails(RouteMachine, 400)
    assert "through_point_not_lying" in found, found
    assert COUNT["steps"] <= 400, COUNT
