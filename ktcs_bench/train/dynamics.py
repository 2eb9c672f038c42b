"""Train dynamics: a point mass with traction and brake limits, gradient, resistance, brake lag.

Owns the physics of the emulated train (the "plant" the ATP/ATO act on), seed 001 Table 1 and
SPEC §6.5: traction up to `max_traction`, service brake `service_decel`, emergency brake
`emergency_decel`, the brake effort building up linearly over `brake_build_up` seconds, the
gradient force g·grad/1000 (‰, uphill positive) and the running resistance A + B·v + C·v² given
per unit mass (m/s²). It never reads a clock: `step(dt, command)` advances by dt.
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.errors import UsageError
from ktcs_bench.train.units import G


@dataclass(frozen=True)
class TrainParams:
    """Physical data of one train (SI units)."""

    length: float = 200.0
    max_speed: float = 80.0 / 3.6
    max_traction: float = 3.0 / 3.6
    """Maximum traction acceleration at low speed, m/s² (seed 001: 3.0 km/h/s)."""
    service_decel: float = 3.0 / 3.6
    emergency_decel: float = 4.0 / 3.6
    brake_build_up: float = 1.0
    """Time for the brake effort to go from 0 to full, s."""
    resistance_a: float = 0.005
    resistance_b: float = 0.0001
    resistance_c: float = 0.00002
    """Running resistance per unit mass: A + B·v + C·v² in m/s² (v in m/s)."""

    def __post_init__(self) -> None:
        for name in ("length", "max_speed", "max_traction", "service_decel", "emergency_decel"):
            if getattr(self, name) <= 0:
                raise UsageError(f"train parameter {name} must be positive")
        if self.brake_build_up < 0:
            raise UsageError("brake_build_up must not be negative")

    def resistance(self, v: float) -> float:
        if v <= 0:
            return 0.0
        return self.resistance_a + self.resistance_b * v + self.resistance_c * v * v


@dataclass(frozen=True)
class Command:
    """What the train is asked to do this step: traction in [0, 1], brake demand in m/s²."""

    traction: float = 0.0
    brake: float = 0.0
    """Requested brake deceleration (0 .. service_decel), m/s²."""
    emergency: bool = False


@dataclass
class TrainState:
    position: float = 0.0
    """Front of the train, m along the line."""
    speed: float = 0.0
    acceleration: float = 0.0
    brake_effort: float = 0.0
    """Brake deceleration actually applied (builds up towards the demand), m/s²."""
    odometer: float = 0.0
    """Total distance travelled, m."""


class TrainDynamics:
    """Integrates one train; the gradient under it comes from a callable (‰ at a location)."""

    def __init__(self, params: TrainParams, state: TrainState | None = None) -> None:
        self.params = params
        self.state = state or TrainState()

    def step(self, dt: float, command: Command, gradient: float = 0.0) -> TrainState:
        """Advance by dt seconds under `command` with `gradient` ‰ under the train."""
        if dt <= 0:
            raise UsageError("dt must be positive")
        p, s = self.params, self.state
        demand = (
            p.emergency_decel
            if command.emergency
            else min(max(command.brake, 0.0), p.service_decel)
        )
        rate = (p.emergency_decel / p.brake_build_up) if p.brake_build_up > 0 else float("inf")
        if demand > s.brake_effort:
            s.brake_effort = min(demand, s.brake_effort + rate * dt)
        else:
            s.brake_effort = max(demand, s.brake_effort - rate * dt)
        traction = 0.0
        if demand == 0.0 and command.traction > 0:
            # traction power limit: constant acceleration up to 1/3 of max speed, then ∝ 1/v
            knee = p.max_speed / 3.0
            cap = p.max_traction if s.speed <= knee else p.max_traction * knee / s.speed
            traction = min(command.traction, 1.0) * cap
        a = traction - s.brake_effort - p.resistance(s.speed) - G * gradient / 1000.0
        if s.speed <= 0.0 and a < 0.0:
            a = 0.0  # at standstill brakes/resistance hold; the bench does not roll back
        v_new = s.speed + a * dt
        if v_new < 0.0:
            # stops within the step: travel until standstill only
            t_stop = s.speed / -a if a < 0 else 0.0
            dx = 0.5 * s.speed * t_stop
            v_new = 0.0
        else:
            dx = 0.5 * (s.speed + v_new) * dt
        s.position += dx
        s.odometer += dx
        s.speed = v_new
        s.acceleration = a
        return s
