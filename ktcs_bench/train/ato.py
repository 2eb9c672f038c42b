"""Urban ATO of seed 002: the application state machine (Table 2, a–j) and the driving laws.

Owns when the ATO may drive and how: time-optimal (full traction or full service brake) far from
the target speed, PI control near it, and precision stop by distance to go (the deceleration needed
to stop at the mark, recomputed every cycle, demanded net of the gradient under the train). Target
speed = ATC code − 3 km/h in normal mode, − 2 km/h in recovery mode. `planned_decel` and
`sbi_margin` say how it plans a braking within its ATP's curves (the endpoint applies them).

Seed 002's Fig. 4 (the diagram) is not in the text; Table 2 gives only the conditions a–j. The
from/to states below are our reading of it and are listed in `TRANSITIONS`:
a Passive→Active-Idle, b Active-*→Passive, c Active-Idle→Active-Operating, d Active-Operating→
Active-Idle, e Operating: code stop (speed command 0 → brake to standstill), f Active-Idle: ATO
Ready withdrawn, g Operating: berthed at a station (standstill within ±DLS/2), h berthed: hold while
the speed command is 0, i any→Error, j Error→Passive on time-out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from ktcs_bench.train.units import kmh


class AtoState(Enum):
    PASSIVE = "passive"
    ACTIVE_IDLE = "active-idle"
    ACTIVE_OPERATING = "active-operating"
    ERROR = "error"


TRANSITIONS: dict[str, tuple[str, str, str]] = {
    "a": ("passive", "active-idle", "Cab Active = True"),
    "b": ("active-*", "passive", "Cab Active = False"),
    "c": ("active-idle", "active-operating", "Activate ATO ∧ comm OK ∧ valid TWC ∧ speed = 0"),
    "d": ("active-operating", "active-idle", "¬Activate ATO ∨ comm not OK ∨ invalid TWC"),
    "e": ("active-operating", "active-operating", "speed command = 0: code stop"),
    "f": ("active-idle", "active-idle", "¬Activate ATO ∨ comm not OK: ATO Ready withdrawn"),
    "g": ("active-operating", "active-operating", "speed = 0 ∧ at station ± DLS/2: berthed"),
    "h": ("active-operating", "active-operating", "speed command = 0 while berthed: hold"),
    "i": ("*", "error", "unrecoverable error"),
    "j": ("error", "passive", "time-out"),
}


@dataclass(frozen=True)
class AtoInputs:
    cab_active: bool = True
    activate_ato: bool = True
    comm_ok: bool = True
    twc_valid: bool = True
    speed: float = 0.0
    speed_command: float = 0.0
    """ATC code speed under the antenna, m/s."""
    at_station: bool = False
    error: bool = False


@dataclass
class AtoStateMachine:
    state: AtoState = AtoState.PASSIVE
    berthed: bool = False
    code_stop: bool = False
    ready: bool = False
    error_since: float | None = None
    error_timeout: float = 5.0

    def step(self, i: AtoInputs, now: float) -> list[str]:
        """Apply Table 2; returns the letters of the transitions taken this cycle."""
        taken: list[str] = []
        s = self.state
        if i.error and s is not AtoState.ERROR:
            self.state, self.error_since = AtoState.ERROR, now
            return ["i"]
        if s is AtoState.ERROR:
            if self.error_since is not None and now - self.error_since >= self.error_timeout:
                self.state = AtoState.PASSIVE
                taken.append("j")
            return taken
        if s is AtoState.PASSIVE:
            if i.cab_active:
                self.state = AtoState.ACTIVE_IDLE
                taken.append("a")
            return taken
        if not i.cab_active:
            self.state, self.berthed, self.code_stop = AtoState.PASSIVE, False, False
            return ["b"]
        if s is AtoState.ACTIVE_IDLE:
            ok = i.activate_ato and i.comm_ok and i.twc_valid
            if ok and i.speed <= 0.0:
                self.state, self.berthed, self.code_stop = AtoState.ACTIVE_OPERATING, False, False
                taken.append("c")
            elif self.ready and not (i.activate_ato and i.comm_ok):
                taken.append("f")
            self.ready = i.activate_ato and i.comm_ok
            return taken
        # ACTIVE_OPERATING
        if not (i.activate_ato and i.comm_ok and i.twc_valid):
            self.state, self.berthed, self.code_stop = AtoState.ACTIVE_IDLE, False, False
            return ["d"]
        if i.speed <= 0.0 and i.at_station and not self.berthed:
            self.berthed = True
            taken.append("g")
        if i.speed_command <= 0.0:
            if self.berthed:
                taken.append("h") if not self.code_stop else None
            elif not self.code_stop:
                taken.append("e")
            self.code_stop = True
        else:
            self.code_stop = False
        return taken


@dataclass
class AtoController:
    """The driving laws; output is (traction 0..1, brake demand m/s²)."""

    service_decel: float
    max_traction: float
    stop_decel: float = 0.6
    """Nominal deceleration the precision-stop profile is planned with, m/s²."""
    band: float = kmh(4.0)
    """Speed error beyond which the time-optimal law acts."""
    creep: float = kmh(1.0)
    """A target speed below this is a stop (PI control would hold a crawl of micrometres/s)."""
    kp: float = 1.2
    ki: float = 0.15
    integral: float = 0.0
    mode: str = "idle"

    def target_speed(self, code_speed: float, recovery: bool) -> float:
        return max(code_speed - kmh(2.0 if recovery else 3.0), 0.0)

    def command(
        self,
        v: float,
        v_target: float,
        distance_to_go: float,
        dt: float,
        slope: float = 0.0,
        stop_decel: float | None = None,
    ) -> tuple[float, float]:
        """One cycle of control towards v_target with a stop `distance_to_go` ahead (inf: none).

        `slope`: what the gradient under the train adds to its deceleration, m/s² (negative on
        a descent); a stop is braked for with the brake demand that gives the deceleration
        needed net of it. `stop_decel`: the deceleration to plan this stop with (default the
        nominal `stop_decel`)."""
        a_stop = self.stop_decel if stop_decel is None else stop_decel
        if math.isfinite(distance_to_go):
            s = max(distance_to_go, 0.0)
            need = v * v / (2.0 * s) if s > 0.01 else (self.service_decel if v > 0 else 0.0)
            if need >= 0.9 * a_stop or s < 0.05:
                self.mode = "precision-stop"
                self.integral = 0.0
                if s <= 0.05:
                    return 0.0, self.service_decel
                return 0.0, min(max(need - slope, 0.0), self.service_decel)
            v_profile = math.sqrt(2.0 * a_stop * s)
            v_target = min(v_target, v_profile)
        if v_target < self.creep:  # nothing worth driving towards: brake to a standstill
            self.mode = "code-stop"
            self.integral = 0.0
            return 0.0, self.service_decel
        e = v_target - v
        if abs(e) > self.band:
            self.mode = "time-optimal"
            self.integral = 0.0
            return (1.0, 0.0) if e > 0 else (0.0, self.service_decel)
        self.mode = "pi"
        self.integral = max(min(self.integral + e * dt, 5.0), -5.0)
        u = self.kp * e + self.ki * self.integral
        if u >= 0:
            return min(u / max(self.max_traction, 1e-6), 1.0), 0.0
        return 0.0, min(-u, self.service_decel)


PLAN_SHARE = 0.8
"""The ATO plans its braking on at most this share of what its service brake gives net of the
gradient, and of the ATP's safe deceleration there: the rest is its reserve."""


def planned_decel(nominal: float, service_net: float, safe: float) -> float:
    """The deceleration the ATO plans a braking with, m/s²: its nominal one, no more than
    `PLAN_SHARE` of the service brake's net of the gradient (`service_net`) and of the ATP's safe
    deceleration (`safe`) there (a small positive floor where a descent leaves no more)."""
    return max(min(nominal, PLAN_SHARE * service_net, PLAN_SHARE * safe), 0.05)


def sbi_margin(lead: float, a_plan: float, a_safe: float, v_to: float, v_foot: float) -> float:
    """How far short of a target the ATO's braking at `a_plan` down to `v_to` must end for the
    train to stay behind the ATP's SBI curve all the way, m.

    The ATP's EBD reaches `v_foot` at the target on the safe deceleration `a_safe`; the SBI
    curve leads it by `lead` seconds (V·lead metres at speed V). A braking that ends m short
    of the target is behind the SBI at every speed v ≥ v_to when

        m ≥ lead·v + (v² − v_foot²)/(2·a_safe) − (v² − v_to²)/(2·a_plan),

    a parabola in v whose top is at v = lead/(2k), k = 1/(2·a_plan) − 1/(2·a_safe) > 0 (a plan
    gentler than the safe deceleration, `planned_decel`). Near a stop it is the SBI's lead that
    matters: lead²/(4k), about a metre for a 0.5 s brake build-up on 0.6 against 1.1 m/s².
    """
    k = 0.5 / a_plan - 0.5 / a_safe
    if k <= 0.0:
        raise ValueError("the planned deceleration must be below the safe one")
    v = max(lead / (2.0 * k), v_to)
    m = lead * v - k * v * v + v_to * v_to / (2.0 * a_plan) - v_foot * v_foot / (2.0 * a_safe)
    return max(m, 0.0)
