"""Runs a scenario in virtual time: every train endpoint stepped each cycle, the wayside around
them (resource manager, point machines, track-circuit codes, protection zones) emulated in-line.

Owns the virtual clock and the records (a trace per train, the event log). Deterministic: the same
file gives the same run. Never sleeps and never reads the wall clock; a progress callback lets the
CLI draw a bar.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from ktcs_bench.scenario.model import Scenario
from ktcs_bench.train.endpoint import CycleInputs, Event, TrackCode, TrainEndpoint
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
    events: list[Event]
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


def run(scn: Scenario, progress: Callable[[float], None] | None = None) -> RunResult:
    trains = [TrainEndpoint(cfg, scn.line) for cfg in scn.trains]
    rm = ResourceManager(list(scn.resources)) if scn.resources is not None else None
    pending_points: list[tuple[float, str, str]] = []
    traces = {t.cfg.train_id: Trace() for t in trains}
    events: list[Event] = []
    messages: dict[str, T2TMessage] = {}
    for t in trains:
        pos = t.position
        messages[t.cfg.train_id] = T2TMessage(t.cfg.train_id, pos.head, pos.min_safe_rear, 0.0, 0.0)
    n_steps = int(round(scn.duration / scn.dt))
    per_train = [(t, t.cfg.train_id, t.cfg.mode == "ktcs", traces[t.cfg.train_id]) for t in trains]
    now = 0.0
    rm_seen = 0
    still = 0
    dt = scn.dt
    for k in range(n_steps):
        now = k * dt
        if rm is not None and pending_points:
            for due, point, position in [p for p in pending_points if p[0] <= now]:
                rm.point_detected(point, position, now)
                pending_points.remove((due, point, position))
        zones = (
            tuple((z.start, z.end) for z in scn.zones if z.active_from <= now < z.active_until)
            if scn.zones
            else ()
        )
        snapshot = tuple(messages.values())
        record_limits = k % RECORD_LIMITS_EVERY == 0
        shared = CycleInputs(snapshot, None, None, False, zones)  # trains without own inputs
        for t, tid, ktcs, tr in per_train:
            inputs = shared
            if rm is not None or ktcs:
                authority = None
                if rm is not None:
                    grant = rm.request(
                        tid,
                        t.position.min_safe_rear,
                        min(t.position.head + 3000.0, scn.line.length),
                        now,
                    )
                    authority = grant.authority_end
                    for cmd in grant.commands:
                        pending_points.append((now + scn.point_throw_time, cmd.point, cmd.position))
                code = code_at(scn, t.state.position) if ktcs else None
                inputs = CycleInputs(snapshot, authority, code, False, zones)
            out = t.step(now, inputs, dt)
            messages[tid] = out.message
            if out.events:
                events.extend(out.events)
            s = t.state
            x = s.position
            tr.t.append(now + dt)
            tr.head.append(x)
            tr.tail.append(x - t.cfg.params.length)
            tr.est_head.append(out.position.head)
            tr.speed.append(s.speed)
            tr.status.append(out.verdict.status.value)
            tr.target.append(out.target_point)
            tr.ebd_at_head.append(t.limits.ebd_at(x))
            if record_limits:
                tr.limits_x.append(out.position.max_safe_front)
                tr.limits_row.append(len(tr.t) - 1)
                for name, v in t.limit_speeds().items():
                    tr.limits.setdefault(name, []).append(v)
        if rm is not None and len(rm.events) > rm_seen:
            for when, text in rm.events[rm_seen:]:
                events.append(Event(when, "RM", "resource", text))
            rm_seen = len(rm.events)
        if progress is not None and k % 50 == 0:
            progress(now / scn.duration)
        if all(t.state.speed <= 0.0 and t.status is not Status.INTERVENTION for t in trains):
            still += 1
        else:
            still = 0
        if scn.stop_when_all_stopped and still * scn.dt >= STILL_S:
            break
    if progress is not None:
        progress(1.0)
    return RunResult(scn, traces, events, now + dt)
