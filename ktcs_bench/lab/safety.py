"""Steps of the whole-system safety search, and running them on a lab (docs/system_safety.md).

A step is a JSON object: one operator command, train action or fault, then `run_s` seconds of the
lab's clock, looked at every `LOOK_S` (each look a `lab.invariants.snapshot` fed to the
`SafetyChecker`: invariants 1-3, 5 and 6). A `settle` step clears every fault (taps restored and
cleared, point and track-circuit faults cleared), lets the line run and looks until each CTC view equals
its IXL and each IXL's occupancy the rails (invariant 4), or says that they never did.

    {"do": "route", "station": 20, "entry": "01", "exit": "11", "action": "set", "run_s": 2}
    {"do": "point", "station": 20, "point": "31", "position": "reverse", "run_s": 2}
    {"do": "signal", "station": 20, "signal": "01", "action": "stop", "run_s": 2}
    {"do": "mode", "station": 20, "mode": "local", "run_s": 2}
    {"do": "ars", "station": 20, "on": false, "run_s": 2}
    {"do": "link", "link": "st20-atc", "fault": {"cmd": "cut"}, "run_s": 2}
    {"do": "point_fault", "station": 20, "point": "31", "run_s": 2}
    {"do": "point_fault", "station": 20, "point": "31", "kind": "crossed", "run_s": 2}
    {"do": "direction", "station": 20, "interval": "1820", "run_s": 2}
    {"do": "tc_fault", "tc": "TC2055", "run_s": 2}
    {"do": "restart", "device": "ixl20", "run_s": 2}
    {"do": "release_eb", "train": "train2001", "run_s": 2}
    {"do": "wait", "run_s": 10}
    {"do": "settle", "run_s": 30}

A failure is saved as a replay file -- the lab file, the seed and the steps -- that
`ktcs-bench lab simulate --replay FILE` runs again on the virtual clock, the same way.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict

from ktcs_bench import kinds
from ktcs_bench import messages as msg
from ktcs_bench.errors import ConfigError
from ktcs_bench.lab.access import LabAccess
from ktcs_bench.lab.invariants import (
    SafetyChecker,
    TrainState,
    Violation,
    snapshot,
    views_agree,
)
from ktcs_bench.station.model import Line

log = logging.getLogger("ktcs_bench.lab")

LOOK_S = 1.0  # how often the lab is looked at while a step runs (lab seconds)
SETTLE_LIMIT_S = 90.0  # how long a settled line may take to agree after its settle time
DO = ("route", "point", "signal", "mode", "ars", "direction", "link", "point_fault", "tc_fault", "restart",
      "release_eb", "wait", "settle")  # fmt: skip


@dataclass
class StepRun:
    """What happened to one step: the answer to its command, the violations found while it ran."""

    step: Mapping[str, Any]
    answer: dict[str, Any]
    violations: list[Violation] = field(default_factory=list)


async def command(access: LabAccess, step: Mapping[str, Any]) -> dict[str, Any]:
    """Carry out a step's command (not its run); the answer of the device, tap or lab."""
    do = step.get("do")
    device_kinds = access.devices
    ctc = next((n for n, k in device_kinds.items() if k == kinds.CTC), kinds.CTC)
    if do in ("route", "point", "signal", "mode", "ars", "direction"):
        obj = {k: v for k, v in step.items() if k not in ("do", "run_s")}
        return await access.device(ctc, {"cmd": do, **obj})
    if do == "link":
        return await access.link(str(step["link"]), dict(step["fault"]))
    if do == "point_fault":
        side = _device_of(device_kinds, kinds.TRACKSIDE, int(step["station"]), access)
        kind = str(step.get("kind", "detection"))
        return await access.device(side, msg.FailPoint(point=str(step["point"]), kind=kind))
    if do == "tc_fault":
        tc = next(n for n, k in device_kinds.items() if k == kinds.TRACKCIRCUIT)
        kind = str(step.get("kind", "failed_occupied"))
        return await access.device(tc, msg.Fail(tc=str(step["tc"]), kind=kind))
    if do == "restart":
        return await access.lab({"cmd": "restart", "device": step["device"]})
    if do == "release_eb":
        return await access.device(str(step[kinds.TRAIN]), msg.ReleaseEb())
    if do == "settle":
        return await clear_faults(access)
    if do == "wait":
        return {"ok": True}
    raise ConfigError("steps", "", f"unknown step {do!r} ({', '.join(DO)})")


def _device_of(device_kinds: Mapping[str, str], kind: str, station: int, access: LabAccess) -> str:
    """The device of `kind` at `station` (lab files name them kind + station: io20, atc20)."""
    names = [n for n, k in device_kinds.items() if k == kind and n.endswith(str(station))]
    if not names:
        raise ConfigError("steps", "", f"no {kind} device of station {station}")
    return names[0]


async def clear_faults(access: LabAccess) -> dict[str, Any]:
    """Every fault off: each tap restored and cleared, every trackside's and the rails' faults."""
    answers = []
    for link in access.links:
        answers.append(await access.link(link, {"cmd": "restore"}))
        answers.append(await access.link(link, {"cmd": "clear"}))
    for name, kind in sorted(access.devices.items()):
        if kind == kinds.TRACKSIDE:
            answers.append(await access.device(name, msg.ClearFaults()))
        elif kind == kinds.TRACKCIRCUIT:
            answers.append(await access.device(name, msg.Clear()))
    failed = [a for a in answers if not a.get("ok")]
    return {"ok": not failed, "failed": failed}


async def run_for(access: LabAccess, checker: SafetyChecker, seconds: float) -> list[Violation]:
    """Let the lab run `seconds`, looking every LOOK_S (and at the end): invariants 1-3."""
    found: list[Violation] = []
    end = access.now() + seconds
    while True:
        left = end - access.now()
        if left <= 1e-9:
            break
        await access.sleep(min(LOOK_S, left))
        found += checker.feed(await snapshot(access, views=False))
    return found


async def settle(access: LabAccess, checker: SafetyChecker, seconds: float) -> list[Violation]:
    """After the faults are cleared: run `seconds`, then look until the views agree (invariant
    4) -- a look where they do ends it; SETTLE_LIMIT_S more without one, the last look's
    disagreements are the violations."""
    found = await run_for(access, checker, seconds)
    deadline = access.now() + SETTLE_LIMIT_S
    while True:
        snap = await snapshot(access)
        found += checker.feed(snap)
        views = views_agree(snap, checker.geo)
        if not views:
            return found
        if access.now() >= deadline:
            checker.violations += views
            return found + views
        found += await run_for(access, checker, LOOK_S)


async def run_step(access: LabAccess, checker: SafetyChecker, step: Mapping[str, Any]) -> StepRun:
    """One step: its command, then its run (a settle step: its settle) with the checks."""
    answer = await command(access, step)
    run_s = float(step.get("run_s", 0.0))
    if step.get("do") == "settle":
        found = await settle(access, checker, run_s)
    else:
        found = await run_for(access, checker, run_s)
    return StepRun(step, answer, found)


async def run_steps(
    access: LabAccess, checker: SafetyChecker, steps: Sequence[Mapping[str, Any]]
) -> list[StepRun]:
    """Every step in turn, all of them (a violation does not stop the run)."""
    checker.feed(await snapshot(access))
    return [await run_step(access, checker, s) for s in steps]


async def replay_steps(access: LabAccess, replay: Replay, line: Line) -> list[StepRun]:
    """A replay file's run on a lab just brought up with its seed: the warm-up, then the steps,
    checked as the search checked them."""
    await access.sleep(replay.warm_up_s)
    return await run_steps(access, SafetyChecker(line), replay.steps)


# ------------------------------------------------------------------------------- a run, watched


LASTING = frozenset({"shared_track_circuit", "collision", "train_rear", "point_moved_under_train",
                     "point_moved_locked", "through_point_not_lying", "opposing_departures",
                     "opposing_trains"})  # fmt: skip
"""Violations that are states (they hold look after look until something changes), as opposed
to moments (a head running past a danger point, onto a point, a point trailed)."""


class Watch:
    """Invariants 1-3 throughout a run of a lab (`lab simulate`): a look (`snapshot`, fed to a
    `SafetyChecker`) after every change of state of an IXL, a trackside or the rails -- whoever
    runs the lab calls `changed()` when one of them logs an event (a route locked, set, entered,
    released; a signal; a point moving or detected; an occupancy change; a fault; a restart) --
    so the interlocking, the blades and what the rails report stand still between two looks and
    none of their states goes unseen. What the rails do not report (a train moving on under a
    track circuit failed clear, or into one another train occupies) is caught by `run`: every
    `LOOK_S` it reads the trains' positions alone and looks when a train's head or axles are in
    other track circuits than at the last look.

    A violation is reported (`on_violation`, and kept in `reported`) when it is found; one of a
    state that lasts (`LASTING`) again only once it has gone away at a look and come back: two
    trains standing in one track circuit are one violation, not one a look."""

    def __init__(
        self,
        access: LabAccess,
        line: Line,
        on_violation: Callable[[Violation], None] | None = None,
    ) -> None:
        self.access = access
        self.checker = SafetyChecker(line)
        self.on_violation = on_violation
        self.reported: list[Violation] = []
        self._standing: set[tuple[int, str, str]] = set()
        self._pending = False
        self._where: tuple[tuple[str, tuple[str, ...], str | None], ...] | None = None
        self._tcs = [n for n, k in access.devices.items() if k == kinds.TRACKCIRCUIT]
        self.closed = False  # the run is over: no more looks

    def changed(self) -> None:
        """A device's state changed: one look when the loop comes round (one for every change
        of the same moment that comes before it)."""
        if self._pending or self.closed:
            return
        self._pending = True
        asyncio.get_running_loop().call_soon(self._spawn)

    def _spawn(self) -> None:
        if self.closed:
            return
        task = asyncio.ensure_future(self.look())
        task.add_done_callback(_log_failure)

    async def look(self) -> list[Violation]:
        """Look now: the new violations."""
        self._pending = False
        snap = await snapshot(self.access, views=False)
        self._where = self._positions(snap.trains)
        return self._report(self.checker.feed(snap))

    async def run(self) -> None:
        """Every LOOK_S: a look if a train's head or axles changed track circuits unreported."""
        while True:
            await self.access.sleep(LOOK_S)
            trains = await self._trains()
            if trains is not None and self._positions(trains) != self._where:
                await self.look()

    async def _trains(self) -> dict[str, TrainState] | None:
        trains: dict[str, TrainState] = {}
        for name in self._tcs:
            answer = await self.access.device(name, msg.Status())
            if not answer.get("ok"):
                return None
            for t, (head, tail, track) in answer["status"].get("trains", {}).items():
                trains[t] = TrainState(t, float(head), float(tail), str(track))
        return trains

    def _positions(
        self, trains: Mapping[str, TrainState]
    ) -> tuple[tuple[str, tuple[str, ...], str | None], ...]:
        geo = self.checker.geo
        return tuple((n, tuple(geo.shunted(t)), geo.tc_at(t.head_m, t.track, t.up))
                     for n, t in sorted(trains.items()))  # fmt: skip

    def _report(self, found: list[Violation]) -> list[Violation]:
        lasting = [v for v in found if v.kind in LASTING]
        keys = {(v.invariant, v.kind, v.where) for v in lasting}
        new = [v for v in found
               if v.kind not in LASTING or (v.invariant, v.kind, v.where) not in self._standing]  # fmt: skip
        self._standing = keys
        for v in new:
            self.reported.append(v)
            if self.on_violation is not None:
                self.on_violation(v)
        return new


def _log_failure(task: asyncio.Task[list[Violation]]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("a look at the lab's invariants failed: %r", task.exception())


# ------------------------------------------------------------------------------------ replay files


class ReplayJson(TypedDict):
    """A replay file's contents (`Replay.to_json`)."""

    lab: str
    seed: int
    warm_up_s: float
    steps: list[Mapping[str, Any]]
    violations: list[str]


@dataclass(frozen=True)
class Replay:
    lab: str  # the lab file
    seed: int
    warm_up_s: float
    steps: tuple[Mapping[str, Any], ...]
    violations: tuple[str, ...] = ()  # what the search saw (for the reader)

    def to_json(self) -> ReplayJson:
        return {"lab": self.lab, "seed": self.seed, "warm_up_s": self.warm_up_s,
                "steps": list(self.steps), "violations": list(self.violations)}  # fmt: skip

    def write(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        return path


def load_replay(path: Path) -> Replay:
    """A replay file, checked: a clear ConfigError naming the file and what is wrong."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise ConfigError(str(path), "", f"not JSON: {exc}") from None
    if not isinstance(raw, dict):
        raise ConfigError(str(path), "", "a replay file is a JSON object")
    steps = raw.get("steps")
    if not isinstance(steps, list) or not all(
        isinstance(s, dict) and s.get("do") in DO for s in steps
    ):
        raise ConfigError(str(path), "steps", f"a list of steps, each with do: one of {DO}")
    try:
        return Replay(str(raw["lab"]), int(raw.get("seed", 0)), float(raw.get("warm_up_s", 0)),
                      tuple(steps), tuple(str(v) for v in raw.get("violations", [])))  # fmt: skip
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(str(path), "", f"lab, seed and warm_up_s: {exc}") from None
