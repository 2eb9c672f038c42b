"""The train endpoint: one train's plant (dynamics) with its onboard ATP, driver/ATO, stepped.

Owns the 100 ms onboard cycle, sans-I/O: `TrainEndpoint.step(now, inputs)` takes what the train
receives this cycle (train-to-train messages, the resource manager's grant, the code under the
antenna, driver actions) and returns what it sends (its T2T message, its resource request) and
what happened (events). Two operating modes:

* ``atcs`` — the ATCS onboard ATP of seeds 000/001: target point = min(end of line, authority end
  from the resource manager, the leader's rear − safety distance, protection zones), MRSP targets
  from the line data, EBD/EBI/SBI supervision with the latched emergency brake;
* ``ktcs`` — the code under the antenna gives the targets: its speed is the speed at the track
  circuit's exit (a speed target there, a stop target when 0), its target distance the stop point,
  and both braking curves use the code's gradient. Inside the track circuit the ceiling is the
  speed the train was allowed to enter with (the previous circuit's code) or this code if higher.
  The endpoint owns this reading; a process adapter only passes the code on (`TrackCode.read`).

The cycle is the train's deadline (the `ktcs_bench.timed` shape): `next_deadline()` is the next
cycle, `first + k·cycle`; `handle_timer(now)` runs it -- reading its inputs through `sense(now)`,
the antenna, radio and driver's desk sampled at the start of the cycle -- and returns its
`CycleOutputs` (None when no cycle was due). A driver (the wall clock in the live lab, the virtual
clock in scenarios) calls it at each deadline; `step(now, inputs)` is the cycle itself, for a
caller that brings the inputs in hand.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ktcs_bench.errors import UsageError
from ktcs_bench.train.ato import (
    AtoController,
    AtoInputs,
    AtoState,
    AtoStateMachine,
    planned_decel,
    sbi_margin,
)
from ktcs_bench.train.curves import (
    CurveSet,
    CurveTimes,
    Grid,
    Target,
    TargetKind,
    curves_from_envelope,
    ebd_envelope,
    ebd_segment,
)
from ktcs_bench.train.deceleration import (
    FloatArray,
    GradientProfile,
    RotatingMass,
    SafeDeceleration,
    StepFunction,
    gradient_acceleration,
)
from ktcs_bench.train.dynamics import Command, TrainDynamics, TrainParams, TrainState
from ktcs_bench.train.mrsp import Restriction, SpeedProfile, build_mrsp
from ktcs_bench.train.position import Position, PositionEstimator, TachoScale
from ktcs_bench.train.supervision import (
    EBI,
    PERMITTED,
    SBI,
    WARNING,
    Status,
    SupervisionLimits,
    SupervisionVerdict,
    Supervisor,
)
from ktcs_bench.train.t2t import T2TMessage, leader_of, target_from_leader
from ktcs_bench.train.units import kmh

CYCLE = 0.1
# a train at rest (`TrainEndpoint.at_rest`) cycles once every this many cycles (once a second)
REST_CYCLES = 10
"""The onboard cycle, s (seed 000: 100 ms)."""
MAX_MA = 3000.0
"""cMAX_MA: the longest authority a train asks for, m."""
CODE_GRIDS = 8
"""kTCS code gradients whose curve grid is kept."""
ATO_REACTION = 1.0
"""The ATO starts braking for a speed target this long (s, at its speed) before its plan says."""


@dataclass(frozen=True)
class TrackCode:
    """A kTCS track-circuit code as read by the antenna, located on the train's line (rising
    positions in its direction of travel: `train.frame`)."""

    speed: float
    """Target speed at the track circuit's exit, m/s (0: stop at the exit)."""
    gradient: float = 0.0
    """Gradient the code gives for braking, ‰ (the lowest under the track circuit)."""
    target_point: float = math.inf
    """Absolute location of the stop point the code's target distance designates, m."""
    start: float = -math.inf
    """Entry end of the track circuit, m."""
    end: float = math.inf
    """Exit end of the track circuit, m: where `speed` applies."""

    @classmethod
    def read(
        cls,
        start: float,
        end: float,
        speed: float,
        gradient: float = 0.0,
        target_distance: float | None = None,
    ) -> TrackCode:
        """The code of track circuit [start, end): its target distance counts from the entry
        end (None: no stop point ahead)."""
        point = math.inf if target_distance is None else start + target_distance
        return cls(speed, gradient, point, start, end)

    @classmethod
    def stop_here(cls, x: float) -> TrackCode:
        """What a train reads with no code at its antenna: stop where it stands."""
        return cls(0.0, 0.0, x, x, x)

    @property
    def stop_point(self) -> float:
        """The nearest place the code says stop: its target point, or its exit for a 0 code."""
        return min(self.target_point, self.end) if self.speed <= 0.0 else self.target_point


class _AtoPlan(NamedTuple):
    """The ATO's braking plan of one cycle (`TrainEndpoint._ato_plan`)."""

    speed: float
    """The highest speed from which it meets every speed target ahead on its plan, m/s."""
    stop_margin: float
    """How far short of the stop it aims, m (beyond the usual half metre)."""
    stop_decel: float
    """The deceleration it plans the stop with, m/s²."""
    slope: float
    """What the gradient under the train adds to its deceleration, m/s²."""


class _Layer(NamedTuple):
    """One moving target's EBD laid over the static one: its values on grid nodes [lo, k)."""

    lo: int
    k: int
    vals: FloatArray
    target: Target
    stop: bool
    """A stop target: the EBD is 0 from node k on."""


@dataclass(frozen=True)
class Station:
    """A platform stop the ATO makes: its front at `stop_mark`, standing `dwell` s, leaving no
    sooner than `depart` (the train's time, s)."""

    name: str
    stop_mark: float
    dwell: float = 20.0
    depart: float = 0.0


@dataclass(frozen=True)
class Arrival:
    """A platform stop made: where the front came to rest, on the plant's (true) position."""

    station: str
    stop_mark: float
    time: float
    head: float

    @property
    def error(self) -> float:
        """Stop error, m: + beyond the mark, − short of it."""
        return self.head - self.stop_mark


@dataclass(frozen=True)
class Departure:
    station: str
    time: float


SERVICE_STATES = ("running", "stopping", "dwelling", "held", "finished", "left")
"""What a train is doing (`TrainEndpoint.service_state`): moving on its codes, braking for a stop,
standing its dwell at a platform, standing for a code (at a signal, or at a platform with its
dwell over) or under the operator's hold, its service over at its last stop, gone off the end of
the line."""
STOP_TOLERANCE = 0.5
"""A platform stop is good within ± this of the mark, m (its doors line up with the platform)."""
BERTH_WINDOW = 1.0
"""The ATO berths at a station standing within ± this of its mark by its own position, m (±DLS/2,
seed 002 Table 2 g)."""
LEAVE_WITHIN = 5.0
"""A train whose service leaves the line has left once it stands this near the line's end, m."""


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
    leaves_line: bool = False
    """After its last station the ATO runs on to the end of the line, and the train leaves."""


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
class TrainEvent:
    time: float
    train: str
    kind: str
    text: str


@dataclass(frozen=True)
class CycleOutputs:
    message: T2TMessage
    request_up_to: float
    verdict: SupervisionVerdict
    position: Position
    target_point: float
    events: tuple[TrainEvent, ...]


def _no_inputs(now: float) -> CycleInputs:
    return CycleInputs()


def _as_is(x: float) -> float:
    return x


class TrainEndpoint:
    """One train: plant + ATP + driver/ATO, cycling every `cycle` s from `first` (see the module
    docstring); `sense(now)` gives a cycle its inputs. It works in rising positions; `chainage`
    tells a place of its own as people name it on the line (a down train's runs against the
    chainage: `train.frame`) in what it says, and `run_to` takes a place of its own."""

    def __init__(
        self,
        cfg: TrainConfig,
        line: LineData,
        *,
        sense: Callable[[float], CycleInputs] = _no_inputs,
        first: float = 0.0,
        cycle: float = CYCLE,
        chainage: Callable[[float], float] = _as_is,
    ) -> None:
        self.cfg, self.line = cfg, line
        self.chainage = chainage
        self.sense = sense
        self.first, self.cycle = first, cycle
        self.cycles = 0
        self._slot = -1  # the cycle slot (first + slot * cycle) the last cycle ran in
        self._rested = False  # the last cycle left it at rest
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
        fixed = self.times.fixed
        self._static_targets = self.mrsp.targets()
        self._static_ebd, self._static_breaks = ebd_envelope(
            self.grid, self._static_targets, fixed, self.v_cap
        )
        self._mrsp_grid = self.mrsp.on_grid(self.grid.x)
        # the supervised EBD = static EBD with the moving targets' curves (stop target, kTCS
        # code) laid over it in place: [0, lo) static, [lo, zero) min(static, layers), [zero, n)
        # 0 (past the nearest stop)
        n = len(self.grid.x)
        self._ebd = self._static_ebd.copy()
        self._lo, self._zero = n, n
        self._stop: float | None = None
        self._stop_layer: _Layer | None = None
        self._code: TrackCode | None = None
        self._code_layers: list[_Layer] = []
        self._code_grids: dict[float, Grid] = {}
        self._entry_speed = 0.0
        self.limits = SupervisionLimits(
            self.grid.x, self._ebd, self._mrsp_grid, tuple(self._static_targets), fixed
        )
        self.ato_sm = AtoStateMachine()
        self.ato_ctl = AtoController(p.service_decel, p.max_traction)
        self.target_point = line.length
        self.eb_count = 0
        self._standstill_since: float | None = None
        self._eb_seen = False
        self._next_station = 0
        self._dwell_until = cfg.depart_at
        self.arrivals: list[Arrival] = []
        self.departures: list[Departure] = []
        self._berth: Station | None = None  # the platform it stands at, until it departs
        self._to_go = math.inf  # the ATO's distance to go to its next stop, m
        self.left = False
        # the operator's orders (`hold`, `dispatch`, `run_to`): "here" stand where it stands (or
        # brake to a stop), "platform" stand at its next platform stop; a commanded stop point
        self._hold: str | None = None
        self._stop_at: float | None = None
        self.tacho = TachoScale(list(line.tags))

    # ------------------------------------------------------------------ the cycle

    def next_deadline(self) -> float:
        """When the next cycle is due: the next slot of `cycle`, REST_CYCLES slots on at rest."""
        return self.first + (self._slot + (REST_CYCLES if self.at_rest else 1)) * self.cycle

    def handle_timer(self, now: float) -> CycleOutputs | None:
        """Run the cycle that is due, with the inputs `sense(now)` reads (None: none was due).
        Its plant steps over the slots since the last cycle; after an order woke a train at rest
        between its slots, it cycles at once and then on the slots again."""
        step = REST_CYCLES if self.at_rest else 1
        due = self._slot + step
        if now < self.first + due * self.cycle:
            return None
        if step == 1 and self._rested:
            # woken from rest between its slots: the slot it is in, the next one after `now`
            due = max(due, int((now - self.first) / self.cycle + 1e-9))
        slots, self._slot = due - self._slot if self.cycles > 0 else 1, due
        self.cycles += 1
        out = self.step(now, self.sense(now), slots * self.cycle)
        self._rested = self.at_rest
        return out

    @property
    def at_rest(self) -> bool:
        """Its service is over and it stands on the ATO's service brake, no order and no EB
        pending: nothing moves it until an order does (which wakes it: `next_deadline` is then
        the next slot), so it cycles once a second instead of every `cycle` (a design decision:
        a lab's finished trains cost little). Never before its first cycle."""
        stations = self.line.stations
        return (
            self.cycles > 0
            and self.cfg.ato
            and bool(stations)
            and self._next_station >= len(stations)
            and not self.cfg.leaves_line
            and self.dynamics.state.speed <= 0.0
            and self._hold is None
            and self._stop_at is None
            and not self.supervisor.eb_latched
            and self.ato_sm.state is AtoState.ACTIVE_OPERATING
        )

    def step(self, now: float, inputs: CycleInputs, dt: float = CYCLE) -> CycleOutputs:
        cfg, p = self.cfg, self.cfg.params
        s = self.dynamics.state
        events: list[TrainEvent] = []
        pos = self.position
        # 1. target points and curves
        stop = self._target_point(pos, inputs)
        code = inputs.code if cfg.mode == "ktcs" else None
        self.target_point = stop if code is None else min(stop, code.stop_point)
        self._rebuild(stop, code)
        # 2. supervision at the max-safe front
        verdict = self.supervisor.check(
            self.limits, pos.max_safe_front, s.speed, max(s.acceleration, 0.0)
        )
        if verdict.emergency_brake and not self._eb_seen:
            self._eb_seen = True
            self.eb_count += 1
            events.append(TrainEvent(now, cfg.train_id, "emergency_brake", verdict.reason or "EB"))
        if verdict.service_brake and self._sb_prev is False:
            events.append(TrainEvent(now, cfg.train_id, "service_brake", "SBI exceeded"))
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
            events.append(TrainEvent(now, cfg.train_id, "eb_release", "driver released the EB"))
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
        self.tacho.update(self.position)
        for tag in missed:
            self.supervisor.trip(f"missed tag {tag}")
            events.append(TrainEvent(now, cfg.train_id, "missed_tag", f"tag {tag} not read"))
        if self._berth is not None and s.speed > 0.0:
            events.append(TrainEvent(now, cfg.train_id, "departure", f"from {self._berth.name}"))
            self.departures.append(Departure(self._berth.name, now))
            self._berth = None
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
        return target

    def _rebuild(self, stop: float, code: TrackCode | None) -> None:
        """Curves of this cycle: the cached static EBD with the moving layers laid over it —
        the stop target at `stop` and, in kTCS mode, the code's targets.

        Only what moved is recomputed: a layer's curve on its window (a few hundred nodes); the
        nodes no layer covers any more are restored from the static EBD.
        """
        if stop == self._stop and code == self._code:
            return
        if code != self._code:
            self._read_code(code)
        if stop != self._stop or self._stop_layer is None:
            self._stop = stop
            self._stop_layer = self._layer(self.grid, Target(stop))
        first, rest = self._stop_layer, self._code_layers
        ebd, static = self._ebd, self._static_ebd
        zero, lo = first.k, first.lo
        for ly in rest:
            if ly.stop and ly.k < zero:
                zero = ly.k
            if ly.lo < lo:
                lo = ly.lo
        lo = min(lo, zero)
        a = min(lo, self._lo)
        # the stop layer's window is set from the static EBD in one pass, the rest restored
        f_lo, f_hi = min(first.lo, zero), min(first.k, zero)
        ebd[a:f_lo] = static[a:f_lo]
        ebd[f_hi:zero] = static[f_hi:zero]
        np.minimum(static[f_lo:f_hi], first.vals[: f_hi - f_lo], out=ebd[f_lo:f_hi])
        for ly in rest:
            hi = min(ly.k, zero)
            if hi > ly.lo:
                seg = ebd[ly.lo : hi]
                np.minimum(seg, ly.vals[: hi - ly.lo], out=seg)
        if zero < self._zero:
            ebd[zero : self._zero] = 0.0
        self._lo, self._zero = lo, zero
        self.limits.set_moving([first.target, *(ly.target for ly in rest)])

    def _layers(self) -> list[_Layer]:
        stop = [] if self._stop_layer is None else [self._stop_layer]
        return [*stop, *self._code_layers]

    def _layer(self, grid: Grid, target: Target) -> _Layer:
        lo, k, vals = ebd_segment(grid, target, self.times.fixed, self.v_cap)
        return _Layer(lo, k, vals, target, target.kind is TargetKind.STOP)

    def _read_code(self, code: TrackCode | None) -> None:
        """A new code (kTCS): the ceiling in its track circuit and its targets.

        Its speed holds at the exit: a speed target there (a stop target for 0), with the
        ceiling V_code beyond it; inside the circuit the ceiling is the speed the train was
        allowed to enter with (the code of the circuit before, when it came from there) or this
        code if higher. Both braking curves use the code's gradient.
        """
        last, self._code = self._code, code
        if code is None:
            self._code_layers = []
            self.limits.mrsp = self._mrsp_grid
            return
        if last is None or code.start != last.start:  # a new track circuit
            came_from_last = last is not None and abs(code.start - last.end) <= 1e-6
            self._entry_speed = last.speed if last is not None and came_from_last else code.speed
        ceiling = max(self._entry_speed, code.speed)
        x = self.grid.x
        self.limits.mrsp = np.minimum(self._mrsp_grid, np.where(x < code.end, ceiling, code.speed))
        grid = self._code_grid(code.gradient)
        layers = []
        if math.isfinite(code.stop_point):
            layers.append(self._layer(grid, Target(code.stop_point)))
        if 0.0 < code.speed < ceiling and math.isfinite(code.end):
            layers.append(self._layer(grid, Target(code.end, code.speed, TargetKind.SPEED)))
        self._code_layers = layers

    def _code_grid(self, gradient: float) -> Grid:
        """The curve grid with a code's gradient under the whole of it (kept per gradient)."""
        grid = self._code_grids.get(gradient)
        if grid is None:
            if len(self._code_grids) >= CODE_GRIDS:  # codes come from the wire: a bounded cache
                del self._code_grids[next(iter(self._code_grids))]
            decel = SafeDeceleration(
                self.decel.brake, GradientProfile(default=gradient), self.decel.rotating
            )
            grid = self._code_grids[gradient] = Grid(self.grid.x, decel)
        return grid

    def _drive(
        self,
        now: float,
        dt: float,
        verdict: SupervisionVerdict,
        inputs: CycleInputs,
        events: list[TrainEvent],
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
        self,
        now: float,
        dt: float,
        verdict: SupervisionVerdict,
        inputs: CycleInputs,
        events: list[TrainEvent],
    ) -> tuple[float, float]:
        cfg, p = self.cfg, self.cfg.params
        s = self.dynamics.state
        code = inputs.code
        # a kTCS code's speed holds at its circuit's exit: inside, the train may run at the speed
        # it entered with towards the code's stop point (the distance to go brakes it there)
        code_speed = verdict.permitted if code is None else max(code.speed, self._entry_speed)
        station = (
            self.line.stations[self._next_station]
            if self._next_station < len(self.line.stations)
            else None
        )
        at_station = (
            station is not None and abs(self.position.head - station.stop_mark) <= BERTH_WINDOW
        )
        ai = AtoInputs(speed=s.speed, speed_command=code_speed, at_station=at_station)
        for letter in self.ato_sm.step(ai, now):
            events.append(
                TrainEvent(
                    now, cfg.train_id, "ato", f"transition {letter} → {self.ato_sm.state.value}"
                )
            )
        if self.ato_sm.state is not AtoState.ACTIVE_OPERATING:
            return 0.0, p.service_decel
        if station is None and self.line.stations and not cfg.leaves_line:
            return 0.0, p.service_decel  # service over: held at the last station
        if self.ato_sm.berthed and station is not None:
            self._berthed(now, station, events)
            return 0.0, p.service_decel
        if self._berth is not None and (code is None or code.speed <= 0.0):
            return 0.0, p.service_decel  # at a platform it leaves only on a proceed code
        if self._stopped_at_order(now, events) or self._hold == "here":
            self._to_go = 0.0  # a service-brake stop: stopping until it stands
            return 0.0, p.service_decel
        v_target = self.ato_ctl.target_speed(code_speed, cfg.recovery)
        v_target = min(v_target, verdict.permitted - kmh(1.0))
        plan = self._ato_plan(code)
        v_target = min(v_target, plan.speed)
        stops = [self.target_point - 0.5 - self.position.uncertainty - plan.stop_margin]
        if station is not None:
            stops.append(station.stop_mark)
        if self._stop_at is not None:  # in the estimate's frame, by the calibrated tacho
            stops.append(self._stop_at + self.position.head - self.tacho.head(self.position))
        dtg = self._to_go = min(stops) - self.position.head
        if station is None and cfg.leaves_line and s.speed <= 0.0 and dtg < LEAVE_WITHIN:
            if not self.left:
                self.left = True
                events.append(TrainEvent(now, cfg.train_id, "left", "off the end of the line"))
            return 0.0, p.service_decel
        return self.ato_ctl.command(
            s.speed, max(v_target, 0.0), dtg, dt, plan.slope, plan.stop_decel
        )

    def _ato_plan(self, code: TrackCode | None) -> _AtoPlan:
        """How the ATO brakes for the targets the ATP supervises, so that a train it drives is
        never beyond the SBI curve (it may pass the permitted and warning curves a little).

        Each target ahead -- the stop, the code's speed at its circuit's exit, a lower MRSP --
        is met on a planned deceleration the train's service brake can give net of the most
        adverse gradient before it (`planned_decel`; the code's gradient, which the ATP brakes
        on, counts), ending `sbi_margin` short of it (the SBI leads the EBD by T_bec + T_bs2 at
        the train's speed) and starting a reaction second early. The brake demand carries the
        gradient under the train (the code's, else the line's) so that the deceleration the
        plan needs is the one the train gets.
        """
        x = self.position.max_safe_front
        v = self.dynamics.state.speed
        code_g = code.gradient if code is not None else math.inf
        rotating, fixed = self.decel.rotating, self.times.fixed
        brake = min(self.decel.brake.values)
        service = self.cfg.params.service_decel
        lead = self.supervisor.look_ahead(SBI)
        nominal = self.ato_ctl.stop_decel
        here = min(code_g, self.decel.gradient.at(x))
        plan = _AtoPlan(
            speed=math.inf,
            stop_margin=0.0,
            stop_decel=nominal,
            slope=gradient_acceleration(here, rotating),
        )
        for t in self.limits.targets:
            if t.location <= x:
                continue
            g = min(code_g, self.decel.gradient.min_between(x, t.location))
            a_g = gradient_acceleration(g, rotating)
            a_safe = brake + a_g
            a_plan = planned_decel(nominal, service + a_g, a_safe)
            if a_plan >= a_safe:  # no safe braking on this descent: the ATP's business
                continue
            margin = sbi_margin(lead, a_plan, a_safe, t.speed, t.foot_speed(fixed))
            if t.kind is TargetKind.STOP:
                if t.location == self.target_point:  # the stop the ATO brakes for
                    plan = plan._replace(stop_margin=margin, stop_decel=a_plan)
                continue
            # looking ahead V·lead, the SBI reads V_target + dV_sbi beyond the target already
            room = max(t.location - margin - x - v * (ATO_REACTION + lead), 0.0)
            reach = math.sqrt(t.speed * t.speed + 2.0 * a_plan * room)
            if reach < plan.speed:
                plan = plan._replace(speed=reach)
        return plan

    def _berthed(self, now: float, station: Station, events: list[TrainEvent]) -> None:
        """Standing at `station`'s mark: an arrival (unless it has not moved since it was put
        there: it starts its service at this platform), then the dwell, no sooner than the
        station's departure time."""
        head = self.dynamics.state.position
        at = self.chainage
        if self.dynamics.state.odometer > 0.0:
            arrival = Arrival(station.name, station.stop_mark, now, head)
            self.arrivals.append(arrival)
            events.append(TrainEvent(now, self.cfg.train_id, "arrival",
                                     f"{station.name}: front at {at(head):.2f} m, "
                                     f"{arrival.error:+.2f} m from the mark"))  # fmt: skip
        self._dwell_until = max(now + station.dwell, station.depart)
        self._berth = station
        if self._hold == "platform":  # the hold takes effect: it stands here past its dwell
            self._hold = "here"
        self._next_station += 1
        self.ato_sm.berthed = False

    # ------------------------------------------------------------------ the operator's orders

    def _stopped_at_order(self, now: float, events: list[TrainEvent]) -> bool:
        """Standing at its commanded stop point: the order is done, it waits for dispatch."""
        x = self._stop_at
        if x is None or self.dynamics.state.speed > 0.0:
            return False
        if abs(self.tacho.head(self.position) - x) > STOP_TOLERANCE:
            return False
        self._stop_at, self._hold = None, "here"
        head, at = self.dynamics.state.position, self.chainage
        events.append(TrainEvent(now, self.cfg.train_id, "stopped",
                                 f"at the commanded stop {at(x):g} m: front at {at(head):.2f} m, "
                                 f"{head - x:+.2f} m; waits for dispatch"))  # fmt: skip
        return True

    def _ato_only(self, what: str) -> None:
        if not self.cfg.ato:
            raise UsageError(f"train {self.cfg.train_id} is driven by hand: {what} is for the ATO")

    def hold(self, now: float) -> str:
        """The operator holds the train (an ATS platform hold): standing, it does not leave where
        it stands; running, it runs on to its next platform stop and stands there past its dwell
        (never stranded between stations); with no platform stop ahead, the ATO brings it to a
        service-brake stop. Until `dispatch`. Returns what it will do."""
        self._ato_only("hold")
        nxt = self.next_stop
        if self.dynamics.state.speed <= 0.0 or nxt is None or self._berth is not None:
            self._hold = "here"
            if self.dynamics.state.speed > 0.0:
                return "held: no platform stop ahead, a service-brake stop"
            return "held where it stands"
        self._hold = "platform"
        return f"held at its next platform stop, {nxt.name} ({self.chainage(nxt.stop_mark):g} m)"

    def dispatch(self, now: float, at_once: bool = False) -> str:
        """Cancel a hold and a commanded stop: the train goes on with its service when its dwell
        is over and no sooner than its timetable -- at once with `at_once` -- and only when the
        code lets it (the ATP is never overridden: on a stop code it stands)."""
        self._ato_only("dispatch")
        self._hold, self._stop_at = None, None
        if at_once:
            self._dwell_until = min(self._dwell_until, now)
        wait = self._dwell_until - now
        code = self._code if self.cfg.mode == "ktcs" else None
        if code is not None and code.speed <= 0.0 and self.dynamics.state.speed <= 0.0:
            return "dispatched: the code is stop, it leaves when the code lets it"
        if wait > 0.0:
            return f"dispatched: leaves in {wait:.0f} s (its dwell or its timetable)"
        return "dispatched"

    def run_to(self, now: float, x: float) -> str:
        """The ATO runs to stop point `x` (m on its line, ahead of the front, where the service
        brake can still stop it) and stands there, its front within ±`STOP_TOLERANCE`, until
        `dispatch`; platform stops on the way are made as usual. A hold is lifted (this is a
        movement order). The codes still govern: it stops short of a stop code's point."""
        self._ato_only("run to")
        s = self.dynamics.state
        head = self.tacho.head(self.position)
        reach = s.speed * s.speed / (2.0 * self.cfg.params.service_decel)
        at = self.chainage
        if not math.isfinite(x) or not head + reach < x <= self.line.length:
            raise UsageError(
                f"train {self.cfg.train_id}: cannot run to {at(x):g} m: a stop point ahead of "
                f"its front ({at(head):.1f} m{f', {reach:.0f} m to stop' if reach else ''}) and "
                f"on the line (to {at(self.line.length):g} m)"
            )
        self._hold, self._stop_at = None, x
        return f"runs to {at(x):g} m and stands there"

    @property
    def held(self) -> bool:
        """The operator's hold is on (standing, or to take effect at its next platform stop)."""
        return self._hold is not None

    @property
    def commanded_stop(self) -> float | None:
        """Where the operator's order stops it: the run-to point, or the platform a hold stands
        it at (m); None: none (or it stands where it is)."""
        if self._stop_at is not None:
            return self._stop_at
        nxt = self.next_stop
        return nxt.stop_mark if self._hold == "platform" and nxt is not None else None

    @property
    def next_stop(self) -> Station | None:
        """The platform stop it runs to next (None: none left)."""
        stations = self.line.stations
        return stations[self._next_station] if self._next_station < len(stations) else None

    def service_state(self, now: float) -> str:
        """One of `SERVICE_STATES`: what the train is doing at `now`."""
        s = self.dynamics.state
        if self.left:
            return "left"
        if s.speed > 0.0:
            braking = s.speed * s.speed / (2.0 * self.ato_ctl.stop_decel) + 2.0 * s.speed
            return "stopping" if self.cfg.ato and self._to_go <= braking else "running"
        over = self.line.stations and self._next_station >= len(self.line.stations)
        if over and not self.cfg.leaves_line:
            return "finished"
        nxt = self.next_stop
        if nxt is not None and abs(self.position.head - nxt.stop_mark) <= BERTH_WINDOW:
            return "stopping"  # at the mark: berthed at the ATO's next cycle
        if self._hold == "here":
            return "held"
        if self._berth is not None and now < self._dwell_until:
            return "dwelling"
        return "held"

    # ------------------------------------------------------------------ for reports

    def limit_speeds(self) -> dict[str, float]:
        """EBI, SBI, warning, permitted and MRSP speeds (and the EBD) at the train's front, m/s.

        Each is the highest speed not beyond its curve, sought below the one before it: a
        speed beyond the EBI is beyond every later curve, so the numbers keep the curves' order
        (permitted ≤ warning ≤ SBI ≤ EBI) to the last bit, not only to the bisection's width.
        """
        sup, lim = self.supervisor, self.limits
        t = self.times
        x = self.position.max_safe_front
        out = {"mrsp": lim.mrsp_at(x), "ebd": lim.ebd_at(x)}
        f = t.fixed
        above = math.inf
        for name, curve, dv in (
            ("ebi", EBI, f.dv_ebi),
            ("sbi", SBI, f.dv_sbi),
            ("warning", WARNING, f.dv_warning),
            ("permitted", PERMITTED, None),
        ):
            ceiling = out["mrsp"] + (dv(out["mrsp"]) if dv is not None else 0.0)
            above = out[name] = sup.limit_speed(lim, x, min(ceiling, above), curve, 25)
        return out

    def curve_set(self) -> CurveSet:
        """Every curve over the whole grid as supervised now (static EBD with the moving
        targets laid over it), for display."""
        ebd, static, zero = self._ebd, self._static_ebd, self._zero
        # where the supervised EBD jumps: a static target whose curve still ends it there, a
        # layer's speed target likewise, the nearest stop
        breaks = {b for b in self._static_breaks if b < zero and ebd[b - 1] == static[b - 1]}
        for ly in self._layers():
            if ly.lo < ly.k < zero and not ly.stop and ebd[ly.k - 1] == ly.vals[-1]:
                breaks.add(ly.k)
        if zero < len(ebd):
            breaks.add(zero)
        lim = self.limits
        return curves_from_envelope(
            self.grid.x, ebd, sorted(breaks), lim.targets, lim.mrsp, self.times
        )

    @property
    def state(self) -> TrainState:
        return self.dynamics.state

    @property
    def status(self) -> Status:
        v = self.supervisor.last
        return v.status if v is not None else Status.NORMAL
