"""Safe deceleration: brake models stepped in speed, the compensated gradient, A_safe(v, x).

Owns seed 001 eqs. 1 and 2 and Subset-026 §3.13.6: A_safe(V, d) = A_brake_safe(V) + A_gradient(d),
with A_gradient = g·Grad_c(d)/(1000 + 10·M_rotating) and Grad_c the lowest gradient under the train
(each rise takes effect one train length late, each fall at once). Gradients are in ‰, uphill
positive. Both a scalar form (exact, event-by-event integration) and a vectorised form (numpy over a
location grid) are offered, because the golden test wants exactness and the ATP cycle wants speed.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ktcs_bench.errors import UsageError
from ktcs_bench.train.units import G

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]


def __getattr__(name: str) -> object:
    """`FloatArray`, with numpy imported on first use: the wayside ATC (`atc.track_codes`) needs
    only the scalar forms, and a device process spares numpy's memory (about 12 MB)."""
    if name == "FloatArray":
        import numpy as np
        import numpy.typing as npt

        return npt.NDArray[np.float64]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class StepFunction:
    """A value stepped in its argument: `values[i]` holds from `steps[i]` (inclusive) upwards."""

    steps: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        if not self.steps or len(self.steps) != len(self.values):
            raise UsageError("a step function needs as many steps as values, at least one")
        if any(b <= a for a, b in zip(self.steps, self.steps[1:], strict=False)):
            raise UsageError("step function steps must increase strictly")

    @classmethod
    def constant(cls, value: float) -> StepFunction:
        return cls((0.0,), (value,))

    def __call__(self, x: float) -> float:
        i = bisect.bisect_right(self.steps, x) - 1
        return self.values[max(i, 0)]

    def next_step_above(self, x: float) -> float:
        """The first step strictly above x (inf when none)."""
        i = bisect.bisect_right(self.steps, x)
        return self.steps[i] if i < len(self.steps) else math.inf

    def scaled(self, factor: StepFunction) -> StepFunction:
        """Pointwise product with another step function (e.g. Kdry·Kwet correction factors)."""
        steps = tuple(sorted(set(self.steps) | set(factor.steps)))
        return StepFunction(steps, tuple(self(s) * factor(s) for s in steps))


@dataclass(frozen=True)
class GradientProfile:
    """Gradient in ‰ (uphill positive) from each location onwards; before the first: `default`."""

    locations: tuple[float, ...] = ()
    gradients: tuple[float, ...] = ()
    default: float = 0.0

    def __post_init__(self) -> None:
        if len(self.locations) != len(self.gradients):
            raise UsageError("gradient profile: as many locations as gradients")
        if any(b <= a for a, b in zip(self.locations, self.locations[1:], strict=False)):
            raise UsageError("gradient profile locations must increase strictly")

    def at(self, x: float) -> float:
        i = bisect.bisect_right(self.locations, x) - 1
        return self.gradients[i] if i >= 0 else self.default

    def compensated(self, train_length: float) -> GradientProfile:
        """Grad_c: the lowest gradient anywhere under a train whose front is at x (seed 001 eq. 2).

        A rise at location p only counts once the rear has passed it (p + L); a fall counts as soon
        as the front reaches it. Built exactly as a new step profile.
        """
        cands = sorted(set(self.locations) | {p + train_length for p in self.locations})
        locs: list[float] = []
        grads: list[float] = []
        for i, x in enumerate(cands):
            nxt = cands[i + 1] if i + 1 < len(cands) else x + 1.0
            mid = 0.5 * (x + nxt)
            g = self.min_between(mid - train_length, mid)
            if not grads or g != grads[-1]:
                locs.append(x)
                grads.append(g)
        default = self.default
        return GradientProfile(tuple(locs), tuple(grads), default)

    def min_between(self, a: float, b: float) -> float:
        """Lowest gradient over [a, b]."""
        g = self.at(a)
        lo = bisect.bisect_right(self.locations, a)
        hi = bisect.bisect_right(self.locations, b)
        for k in range(lo, hi):
            g = min(g, self.gradients[k])
        return g

    def breakpoints(self) -> tuple[float, ...]:
        return self.locations

    def on_grid(self, x: FloatArray) -> FloatArray:
        """Vectorised lookup of the gradient at every location of `x`."""
        import numpy as np

        if not self.locations:
            return np.full_like(x, self.default)
        idx = np.searchsorted(np.asarray(self.locations), x, side="right") - 1
        vals = np.concatenate(([self.default], np.asarray(self.gradients)))
        return vals[idx + 1]


@dataclass(frozen=True)
class RotatingMass:
    """Rotating-mass allowance in %: the train's nominal value if known, else the fixed bounds."""

    nominal: float | None = None
    minimum: float = 2.0
    maximum: float = 15.0

    def factor(self, gradient: float) -> float:
        """g/(1000 + 10·M) for this gradient (uphill takes M_max, downhill M_min, as Subset-026)."""
        if self.nominal is not None:
            m = self.nominal
        else:
            m = self.maximum if gradient > 0 else self.minimum
        return G / (1000.0 + 10.0 * m)


def gradient_acceleration(gradient: float, rotating: RotatingMass) -> float:
    """A_gradient in m/s² for a gradient in ‰ (positive helps braking)."""
    return gradient * rotating.factor(gradient)


@dataclass(frozen=True)
class SafeDeceleration:
    """A_safe(v, x) = brake(v) + A_gradient(Grad_c(x)); v in m/s, x the train front's location."""

    brake: StepFunction
    """Safe brake deceleration (already corrected), stepped in speed (m/s)."""
    gradient: GradientProfile = field(default_factory=GradientProfile)
    """The compensated gradient (call `GradientProfile.compensated` first)."""
    rotating: RotatingMass = field(default_factory=RotatingMass)

    def at(self, v: float, x: float) -> float:
        return self.brake(v) + gradient_acceleration(self.gradient.at(x), self.rotating)

    def gradient_accel_grid(self, x: FloatArray) -> FloatArray:
        import numpy as np

        g = self.gradient.on_grid(x)
        if self.rotating.nominal is not None:
            m = np.full_like(g, self.rotating.nominal)
        else:
            m = np.where(g > 0, self.rotating.maximum, self.rotating.minimum)
        result: FloatArray = g * G / (1000.0 + 10.0 * m)
        return result


def constant_brake(deceleration: float) -> StepFunction:
    return StepFunction.constant(deceleration)


def speed_steps(values: Sequence[tuple[float, float]]) -> StepFunction:
    """Build a brake model from (speed from, deceleration) pairs, speeds in m/s."""
    pairs = sorted(values)
    return StepFunction(tuple(p[0] for p in pairs), tuple(p[1] for p in pairs))
