"""Runs a scenario in virtual time: every train endpoint stepped each cycle, the wayside around
them (resource manager, point machines, track-circuit codes, protection zones) emulated in-line.

The trains and the wayside are cores on one `ktcs_bench.timed.virtual.VirtualClock`, each
instant a cycle: the wayside first, then every train (its cycle is its deadline; it reads its
inputs from the wayside), then the bookkeeping. Owns the records (a trace per train, the event
log). Deterministic: the same file gives the same run. Never sleeps and never reads the wall clock;
a progress callback lets the CLI draw a bar.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

from ktcs_bench.scenario.model import Scenario
from ktcs_bench.timed.virtual import VirtualClock
from ktcs_bench.train.endpoint import (
    CycleInputs,
    CycleOutputs,
    TrackCode,
    TrainEndpoint,
    TrainEvent,
)
from ktcs_bench.train.resources import ResourceManager
from ktcs_bench.train.supervision import Status
from ktcs_bench.train.t2t import T2TMessage

STILL_S = 60.0
"""With stop_when_all_stopped, the run ends after every train has stood still this long."""
RECORD_LIMITS_EVERY = 10
"""Cycles between samples of the supervision limits at the train (they cost a few bisections)."""


@dataclass
class Trace:
    t: list[float] = field(default_factory=list)
    head: list[float] = field(default_factory=list)
    tail: list[float] = field(default_factory=list)
    est_head: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    status: list[str] = field(default_factory=list)
    target: list[float] = field(default_factory=list)
    ebd_at_head: list[float] = field(default_factory=list)
    """EBD speed at the true front each cycle (for the 'never exceeds EBD' check)."""
    limits_x: list[float] = field(default_factory=list)
    """Where the supervision limits were sampled (the max-safe front), every few cycles."""
    limits_row: list[int] = field(default_factory=list)
    """The trace row (cycle) of each sample."""
    limits: dict[str, list[float]] = field(default_factory=dict)


@dataclass
class RunResult:
    scenario: Scenario
    traces: dict[str, Trace]
    events: list[TrainEvent]
    end_time: float


def code_at(scn: Scenario, x: float) -> TrackCode | None:
    """The kTCS code under an antenna at x: its speed at the circuit's exit, the stop point its
    target distance designates, and the lowest gradient under the circuit (as the wayside ATC
    gives it)."""
    for tc in scn.track_circuits:
        if tc.start <= x < tc.end:
            gradient = scn.line.gradient.min_between(tc.start, tc.end)
            return TrackCode.read(tc.start, tc.end, tc.speed, gradient, tc.target_distance)
    return None


class _Wayside:
    """The wayside around the trains, on their cycle and before them in each instant: the
    resource manager's point machines (a throw ordered is detected at the first cycle after it
    ends), the protection zones in force and the train-to-train radio (each train hears what the
    others sent in the cycle before)."""

    def __init__(self, scn: Scenario, rm: ResourceManager | None, messages: dict[str, T2TMessage]):
        self.scn, self.rm, self.messages = scn, rm, messages
        self.pending_points: list[tuple[float, str, str]] = []
        self.cycles = 0
        self.snapshot: tuple[T2TMessage, ...] = ()
        self.zones: tuple[tuple[float, float], ...] = ()
        self.shared = CycleInputs()

    def next_deadline(self) -> float:
        return self.cycles * self.scn.dt

    def handle_timer(self, now: float) -> None:
        self.cycles += 1
        rm, scn = self.rm, self.scn
        if rm is not None and self.pending_points:
            for due, point, position in [p for p in self.pending_points if p[0] <= now]:
                rm.point_detected(point, position, now)
                self.pending_points.remove((due, point, position))
        self.zones = (
            tuple((z.start, z.end) for z in scn.zones if z.active_from <= now < z.active_until)
            if scn.zones
            else ()
        )
        self.snapshot = tuple(self.messages.values())
        self.shared = CycleInputs(self.snapshot, None, None, False, self.zones)

    def inputs(self, t: TrainEndpoint, now: float) -> CycleInputs:
        """What train `t` receives this cycle: its grant, the code under its antenna."""
        ktcs = t.cfg.mode == "ktcs"
        rm, scn = self.rm, self.scn
        if rm is None and not ktcs:
            return self.shared  # trains without inputs of their own
        authority = None
        if rm is not None:
            grant = rm.request(
                t.cfg.train_id,
                t.position.min_safe_rear,
                min(t.position.head + 3000.0, scn.line.length),
                now,
            )
            authority = grant.authority_end
            for cmd in grant.commands:
                self.pending_points.append((now + scn.point_throw_time, cmd.point, cmd.position))
        code = code_at(scn, t.state.position) if ktcs else None
        return CycleInputs(self.snapshot, authority, code, False, self.zones)


def run(scn: Scenario, progress: Callable[[float], None] | None = None) -> RunResult:
    """Every train and the wayside on one virtual clock, cycle by cycle, for `scn.duration` (or
    until every train has stood still `STILL_S`, when the scenario asks)."""
    dt = scn.dt
    clock = VirtualClock()
    rm = ResourceManager(list(scn.resources)) if scn.resources is not None else None
    trains = [TrainEndpoint(cfg, scn.line, cycle=dt) for cfg in scn.trains]
    traces = {t.cfg.train_id: Trace() for t in trains}
    events: list[TrainEvent] = []
    messages: dict[str, T2TMessage] = {}
    for t in trains:
        pos = t.position
        messages[t.cfg.train_id] = T2TMessage(t.cfg.train_id, pos.head, pos.min_safe_rear, 0.0, 0.0)
    wayside = _Wayside(scn, rm, messages)
    clock.add(wayside)
    for t in trains:
        t.sense = functools.partial(wayside.inputs, t)
        clock.add(t, functools.partial(_record, t, traces[t.cfg.train_id], messages, events))
    after = _AfterCycle(scn, trains, rm, events, progress)
    clock.add(after)
    n_steps = int(round(scn.duration / dt))
    clock.run_until((n_steps - 1) * dt, stop=lambda: after.done)
    if progress is not None:
        progress(1.0)
    return RunResult(scn, traces, events, clock.now + dt)


def _record(
    t: TrainEndpoint,
    tr: Trace,
    messages: dict[str, T2TMessage],
    events: list[TrainEvent],
    now: float,
    out: CycleOutputs | None,
) -> None:
    """One train's cycle into its trace (and its T2T message onto the radio)."""
    if out is None:
        return
    messages[t.cfg.train_id] = out.message
    if out.events:
        events.extend(out.events)
    s = t.state
    x = s.position
    tr.t.append(now + t.cycle)
    tr.head.append(x)
    tr.tail.append(x - t.cfg.params.length)
    tr.est_head.append(out.position.head)
    tr.speed.append(s.speed)
    tr.status.append(out.verdict.status.value)
    tr.target.append(out.target_point)
    tr.ebd_at_head.append(t.limits.ebd_at(x))
    if (t.cycles - 1) % RECORD_LIMITS_EVERY == 0:
        tr.limits_x.append(out.position.max_safe_front)
        tr.limits_row.append(len(tr.t) - 1)
        for name, v in t.limit_speeds().items():
            tr.limits.setdefault(name, []).append(v)


class _AfterCycle:
    """Last in each instant, once every train has run its cycle: the resource manager's events
    into the log, progress, and whether every train has stood still long enough to stop."""

    def __init__(
        self,
        scn: Scenario,
        trains: list[TrainEndpoint],
        rm: ResourceManager | None,
        events: list[TrainEvent],
        progress: Callable[[float], None] | None,
    ) -> None:
        self.scn, self.trains, self.rm, self.events, self.progress = (
            scn,
            trains,
            rm,
            events,
            progress,
        )
        self.cycles = 0
        self.rm_seen = 0
        self.still = 0
        self.done = False

    def next_deadline(self) -> float:
        return self.cycles * self.scn.dt

    def handle_timer(self, now: float) -> None:
        k = self.cycles
        self.cycles += 1
        rm, scn = self.rm, self.scn
        if rm is not None and len(rm.events) > self.rm_seen:
            for when, text in rm.events[self.rm_seen :]:
                self.events.append(TrainEvent(when, "RM", "resource", text))
            self.rm_seen = len(rm.events)
        if self.progress is not None and k % 50 == 0:
            self.progress(now / scn.duration)
        if all(t.state.speed <= 0.0 and t.status is not Status.INTERVENTION for t in self.trains):
            self.still += 1
        else:
            self.still = 0
        self.done = scn.stop_when_all_stopped and self.still * scn.dt >= STILL_S
