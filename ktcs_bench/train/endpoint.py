"""The train endpoint: one train's plant (dynamics) with its onboard ATP, driver/ATO, stepped.

Owns the 100 ms onboard cycle, sans-I/O: `TrainEndpoint.step(now, inputs)` takes what the train
receives this cycle (train-to-train messages, the resource manager's grant, the code under the
antenna, driver actions) and returns what it sends (its T2T message, its resource request) and
what happened (events). Two operating modes:

* ``atcs`` — the ATCS onboard ATP of seeds 000/001: target point = min(end of line, authority end
  from the resource manager, the leader's rear − safety distance, protection zones), MRSP targets
  from the line data, EBD/EBI/SBI supervision with the latched emergency brake;
* ``ktcs`` — the code under the antenna (target speed, gradient, target distance) replaces the
  line's speed data: the ceiling is the code speed and the stop target the code's target point.

A process adapter (the live lab) only has to call `step` every `CYCLE` seconds of wall time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ktcs_bench.train.ato import AtoController, AtoInputs, AtoState, AtoStateMachine
from ktcs_bench.train.curves import (
    CurveTimes,
    Grid,
    Target,
    TargetKind,
    ebd_min_on_grid,
    ebd_segment,
)
from ktcs_bench.train.deceleration import (
    GradientProfile,
    RotatingMass,
    SafeDeceleration,
    StepFunction,
)
from ktcs_bench.train.dynamics import Command, TrainDynamics, TrainParams, TrainState
from ktcs_bench.train.mrsp import Restriction, SpeedProfile, build_mrsp
from ktcs_bench.train.position import Position, PositionEstimator
from ktcs_bench.train.supervision import Status, SupervisionLimits, Supervisor, Verdict
from ktcs_bench.train.t2t import T2TMessage, leader_of, target_from_leader
from ktcs_bench.train.units import kmh

CYCLE = 0.1
"""The onboard cycle, s (seed 000: 100 ms)."""
MAX_MA = 3000.0
"""cMAX_MA: the longest authority a train asks for, m."""


@dataclass(frozen=True)
class TrackCode:
    """A kTCS track-circuit code as read by the antenna."""

    speed: float
    """Target speed, m/s (0: stop)."""
    gradient: float = 0.0
    target_point: float = math.inf
    """Absolute location of the stop point the code's target distance designates, m."""


@dataclass(frozen=True)
class Station:
    name: str
    stop_mark: float
    dwell: float = 20.0


@dataclass
class LineData:
    length: float
    tags: list[float] = field(default_factory=list)
    gradient: GradientProfile = field(default_factory=GradientProfile)
    restrictions: list[Restriction] = field(default_factory=list)
    stations: list[Station] = field(default_factory=list)


@dataclass
class TrainConfig:
    train_id: str
    params: TrainParams
    start: float
    mode: str = "atcs"
    """"atcs" or "ktcs"."""
    driver_speed: float = kmh(80.0)
    """The driver's (or ATO's) wish when the line allows it, m/s."""
    ato: bool = False
    recovery: bool = False
    safety_distance: float = 50.0
    service_brake_enabled: bool = True
    inattentive_until_eb: bool = False
    """Driver ignores the limits until the first emergency brake (to provoke an EBI, seed 001)."""
    eb_release_delay: float | None = 5.0
    """Seconds at standstill after which the driver releases a latched EB (None: never)."""
    tacho_error: float = 0.01
    read_window: float = 1.0
    missed_tags: frozenset[int] = frozenset()
    safe_decel_factor: float = 1.0
    """A_brake_safe = factor × emergency deceleration."""
    service_brake_command: bool = True
    depart_at: float = 0.0


@dataclass(frozen=True)
class CycleInputs:
    messages: tuple[T2TMessage, ...] = ()
    authority_end: float | None = None
    code: TrackCode | None = None
    release_eb: bool = False
    protection_zones: tuple[tuple[float, float], ...] = ()
    gradient: float | None = None
    """True gradient under the train, ‰ (the plant's; None: from the line data)."""


@dataclass(frozen=True)
class Event:
    time: float
    train: str
    kind: str
    text: str


@dataclass(frozen=True)
class CycleOutputs:
    message: T2TMessage
    request_up_to: float
    verdict: Verdict
    position: Position
    target_point: float
    events: tuple[Event, ...]


class TrainEndpoint:
    """One train: plant + ATP + driver/ATO. Step it every CYCLE with an explicit `now`."""

    def __init__(self, cfg: TrainConfig, line: LineData) -> None:
        self.cfg, self.line = cfg, line
        p = cfg.params
        self.dynamics = TrainDynamics(p, TrainState(position=cfg.start))
        self.estimator = PositionEstimator(
            list(line.tags), p.length, cfg.tacho_error, cfg.read_window, cfg.missed_tags
        )
        self.position = self.estimator.start(cfg.start)
        brake = StepFunction.constant(p.emergency_decel * cfg.safe_decel_factor)
        self.decel = SafeDeceleration(brake, line.gradient.compensated(p.length), RotatingMass())
        self.times = CurveTimes(
            t_be=p.brake_build_up,
            t_bs=p.brake_build_up,
            t_traction=CYCLE,  # the train may accelerate for one cycle before the EBI is seen
            service_brake_command=cfg.service_brake_command and cfg.service_brake_enabled,
        )
        self.supervisor = Supervisor(self.times, cfg.service_brake_enabled)
        self.grid = Grid.uniform(0.0, line.length, 1.0, self.decel)
        self.v_cap = p.max_speed + kmh(20.0)
        self.mrsp: SpeedProfile = build_mrsp(
            line.restrictions, p.max_speed, p.length, "full_supervision", 0.0, line.length
        )
        self._static_ebd = ebd_min_on_grid(
            self.grid, self.mrsp.targets(), self.times.fixed, self.v_cap
        )
        self._mrsp_grid = self.mrsp.on_grid(self.grid.x)
        # the supervised EBD = static EBD with the moving stop target's curve laid over it in
        # place: [0, lo) static, [lo, k) min(static, stop curve), [k, n) 0 (past the target)
        n = len(self.grid.x)
        self._ebd = self._static_ebd.copy()
        self._stop: float | None = None
        self._stop_lo, self._stop_k = n, n
        self._code_speed: float | None = None
        self.limits = SupervisionLimits(self.grid.x, self._ebd, self._mrsp_grid)
        self.ato_sm = AtoStateMachine()
        self.ato_ctl = AtoController(p.service_decel, p.max_traction)
        self.target_point = line.length
        self.eb_count = 0
        self._standstill_since: float | None = None
        self._eb_seen = False
        self._next_station = 0
        self._dwell_until = cfg.depart_at
        self._last_code: TrackCode | None = None
        self._ktcs_ceiling = p.max_speed
        self.last_limits_kind = cfg.mode

    # ------------------------------------------------------------------ the cycle

    def step(self, now: float, inputs: CycleInputs, dt: float = CYCLE) -> CycleOutputs:
        cfg, p = self.cfg, self.cfg.params
        s = self.dynamics.state
        events: list[Event] = []
        pos = self.position
        # 1. target point and curves
        target = self._target_point(pos, inputs)
        if target != self.target_point:
            self.target_point = target
        self._rebuild(target, inputs)
        # 2. supervision at the max-safe front
        verdict = self.supervisor.check(
            self.limits, pos.max_safe_front, s.speed, max(s.acceleration, 0.0)
        )
        if verdict.emergency_brake and not self._eb_seen:
            self._eb_seen = True
            self.eb_count += 1
            events.append(Event(now, cfg.train_id, "emergency_brake", verdict.reason or "EB"))
        if verdict.service_brake and self._sb_prev is False:
            events.append(Event(now, cfg.train_id, "service_brake", "SBI exceeded"))
        self._sb_prev = verdict.service_brake
        # 3. driver or ATO
        traction, brake = self._drive(now, dt, verdict, inputs, events)
        if s.speed <= 0.0:
            self._standstill_since = (
                self._standstill_since if self._standstill_since is not None else now
            )
        else:
            self._standstill_since = None
        release = inputs.release_eb
        if (
            self.supervisor.eb_latched
            and cfg.eb_release_delay is not None
            and self._standstill_since is not None
            and now - self._standstill_since >= cfg.eb_release_delay
        ):
            release = True
        if release and self.supervisor.eb_latched and s.speed <= 0.0:
            self.supervisor.release()
            self._eb_seen = False
            events.append(Event(now, cfg.train_id, "eb_release", "driver released the EB"))
        if verdict.traction_cut:
            traction = 0.0
        if verdict.service_brake:
            brake = max(brake, p.service_decel)
        cmd = Command(traction=traction, brake=brake, emergency=verdict.emergency_brake)
        # 4. plant
        grad = (
            inputs.gradient
            if inputs.gradient is not None
            else self.line.gradient.at(s.position - p.length / 2.0)
        )
        x0 = s.position
        self.dynamics.step(dt, cmd, grad)
        self.position, missed = self.estimator.advance(x0, s.position)
        for tag in missed:
            self.supervisor.trip(f"missed tag {tag}")
            events.append(Event(now, cfg.train_id, "missed_tag", f"tag {tag} not read"))
        pos = self.position
        msg = T2TMessage(cfg.train_id, pos.head, pos.min_safe_rear, s.speed, now)
        up_to = min(pos.head + MAX_MA, self.line.length)
        return CycleOutputs(msg, up_to, verdict, pos, self.target_point, tuple(events))

    _sb_prev: bool = False

    # ------------------------------------------------------------------ helpers

    def _target_point(self, pos: Position, inputs: CycleInputs) -> float:
        target = self.line.length
        if inputs.authority_end is not None:
            target = min(target, inputs.authority_end)
        if inputs.messages:
            leader = leader_of(self.cfg.train_id, pos.head, inputs.messages)
            if leader is not None:
                target = min(target, target_from_leader(leader, self.cfg.safety_distance))
        for start, end in inputs.protection_zones:
            if end > pos.min_safe_rear and start > pos.head - 1.0:
                target = min(target, start)
        if self.cfg.mode == "ktcs" and inputs.code is not None:
            target = min(target, inputs.code.target_point)
        return target

    def _rebuild(self, target: float, inputs: CycleInputs) -> None:
        """Curves of this cycle: cached MRSP targets + the moving stop target (+ kTCS code).

        Only what moved is recomputed: the stop target's curve on its window (a few hundred
        nodes), and the nodes it no longer covers are restored from the static EBD.
        """
        if target != self._stop:
            self._stop = target
            stop = Target(target, 0.0, TargetKind.STOP)
            lo, k, vals = ebd_segment(self.grid, stop, self.times.fixed, self.v_cap)
            ebd, static = self._ebd, self._static_ebd
            old_lo, old_k = self._stop_lo, self._stop_k
            if old_lo < lo:  # uncovered by the new window: static again
                ebd[old_lo:lo] = static[old_lo:lo]
            np.minimum(static[lo:k], vals, out=ebd[lo:k])
            if k < old_k:
                ebd[k:old_k] = 0.0
            self._stop_lo, self._stop_k = min(lo, k), k
        if self.cfg.mode == "ktcs" and inputs.code is not None:
            code = inputs.code
            if code != self._last_code:
                self._last_code = code
            if code.speed != self._code_speed:
                self._code_speed = code.speed
                self.limits.mrsp = np.minimum(self._mrsp_grid, code.speed)
        elif self._code_speed is not None:
            self._code_speed = None
            self.limits.mrsp = self._mrsp_grid

    def _drive(
        self, now: float, dt: float, verdict: Verdict, inputs: CycleInputs, events: list[Event]
    ) -> tuple[float, float]:
        cfg, p = self.cfg, self.cfg.params
        s = self.dynamics.state
        if now < self._dwell_until:
            return 0.0, p.service_decel
        if cfg.ato:
            return self._ato(now, dt, verdict, inputs, events)
        wish = cfg.driver_speed
        if not (cfg.inattentive_until_eb and self.eb_count == 0):
            # the driver looks ahead by the brake build-up time plus a reaction second
            ahead = self.position.max_safe_front + s.speed * (p.brake_build_up + 1.0)
            wish = min(
                wish,
                verdict.permitted - kmh(2.0),
                self.supervisor.permitted_speed(self.limits, ahead) - kmh(2.0),
            )
            # brake for a stop target in good time (the driver reads the DMI's target distance)
            dtg = self.target_point - self.position.max_safe_front
            if dtg < 5.0:
                wish = 0.0
        if s.speed < wish - kmh(1.0):
            return 1.0, 0.0
        if s.speed > wish + kmh(1.0):
            return 0.0, p.service_decel
        return 0.0, 0.0

    def _ato(
        self, now: float, dt: float, verdict: Verdict, inputs: CycleInputs, events: list[Event]
    ) -> tuple[float, float]:
        cfg, p = self.cfg, self.cfg.params
        s = self.dynamics.state
        code_speed = inputs.code.speed if inputs.code is not None else verdict.permitted
        station = (
            self.line.stations[self._next_station]
            if self._next_station < len(self.line.stations)
            else None
        )
        at_station = station is not None and abs(self.position.head - station.stop_mark) <= 1.0
        ai = AtoInputs(speed=s.speed, speed_command=code_speed, at_station=at_station)
        for letter in self.ato_sm.step(ai, now):
            events.append(
                Event(now, cfg.train_id, "ato", f"transition {letter} → {self.ato_sm.state.value}")
            )
        if self.ato_sm.state is not AtoState.ACTIVE_OPERATING:
            return 0.0, p.service_decel
        if station is None and self.line.stations:
            return 0.0, p.service_decel  # service over: held at the last station
        if self.ato_sm.berthed and station is not None:
            events.append(
                Event(now, cfg.train_id, "berthed", f"{station.name} at {self.position.head:.2f} m")
            )
            self._dwell_until = now + station.dwell
            self._next_station += 1
            self.ato_sm.berthed = False
            return 0.0, p.service_decel
        v_target = self.ato_ctl.target_speed(code_speed, cfg.recovery)
        v_target = min(v_target, verdict.permitted - kmh(1.0))
        stops = [self.target_point - 0.5 - self.position.uncertainty]
        if station is not None:
            stops.append(station.stop_mark)
        dtg = min(stops) - self.position.head
        return self.ato_ctl.command(s.speed, max(v_target, 0.0), dtg, dt)

    # ------------------------------------------------------------------ for reports

    def limit_speeds(self) -> dict[str, float]:
        """EBI, SBI, warning, permitted, indication and MRSP speeds at the train's front (m/s)."""
        sup, lim = self.supervisor, self.limits
        t = self.times
        x = self.position.max_safe_front
        out = {"mrsp": lim.mrsp_at(x), "ebd": lim.ebd_at(x)}
        f = t.fixed
        for name, lead, dv in (
            ("ebi", 0.0, f.dv_ebi),
            ("sbi", t.t_bs2, f.dv_sbi),
            ("warning", t.t_bs2 + f.t_warning, f.dv_warning),
            ("permitted", t.t_bs2 + f.t_driver, None),
        ):
            ceiling = out["mrsp"] + (dv(out["mrsp"]) if dv is not None else 0.0)
            out[name] = sup.limit_speed(lim, x, ceiling, lead, 25)
        return out

    @property
    def state(self) -> TrainState:
        return self.dynamics.state

    @property
    def status(self) -> Status:
        v = self.supervisor.last
        return v.status if v is not None else Status.NORMAL
