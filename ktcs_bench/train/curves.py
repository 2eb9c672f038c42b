"""Braking curves of Subset-026 §3.13: EBD, EBI, SBI, warning, permitted and indication.

Owns the curve arithmetic only (no state, no clock). Two forms:

* exact scalars for one target — `ebd_distance(...)` walks back from the target event by event
  (speed steps of the brake model, steps of the compensated gradient) and is what the golden ERA
  frames are checked against;
* a vectorised grid form for the ATP cycle — `ebd_on_grid(...)` gives the EBD speed at every
  location of a 1 m grid, in closed form per brake-model speed band (v² is linear in distance plus
  the cumulative gradient term), so a 15 km line costs a few numpy passes.

The supervision limits come from the EBD by the time offsets of §3.13.9.3 (`CurveTimes`): the EBI
sits `D_bec` before the EBD at the speed `V_bec`, the SBI2 another `V·T_bs2`, then warning,
permitted and indication by `T_warning`, `T_driver` and `T_indication`. Ceiling limits are
`V_MRSP + dV` with the fixed values of A.3.1 (`FixedValues`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from ktcs_bench.errors import UsageError
from ktcs_bench.train.deceleration import FloatArray, SafeDeceleration
from ktcs_bench.train.units import kmh

_EPS = 1e-9


def _ramp(v: float, dv_min: float, dv_max: float, v_min: float, v_max: float) -> float:
    if v <= v_min:
        return dv_min
    c = (dv_max - dv_min) / (v_max - v_min)
    return min(dv_min + c * (v - v_min), dv_max)


@dataclass(frozen=True)
class FixedValues:
    """Subset-026 A.3.1 fixed values used by the curves, in SI units."""

    dv_ebi_min: float = kmh(7.5)
    dv_ebi_max: float = kmh(15.0)
    v_ebi_min: float = kmh(110.0)
    v_ebi_max: float = kmh(210.0)
    dv_sbi_min: float = kmh(5.5)
    dv_sbi_max: float = kmh(10.0)
    v_sbi_min: float = kmh(110.0)
    v_sbi_max: float = kmh(210.0)
    dv_warning_min: float = kmh(4.0)
    dv_warning_max: float = kmh(5.0)
    v_warning_min: float = kmh(110.0)
    v_warning_max: float = kmh(140.0)
    t_warning: float = 2.0
    t_driver: float = 4.0

    def dv_ebi(self, v: float) -> float:
        return _ramp(v, self.dv_ebi_min, self.dv_ebi_max, self.v_ebi_min, self.v_ebi_max)

    def dv_sbi(self, v: float) -> float:
        return _ramp(v, self.dv_sbi_min, self.dv_sbi_max, self.v_sbi_min, self.v_sbi_max)

    def dv_warning(self, v: float) -> float:
        return _ramp(
            v, self.dv_warning_min, self.dv_warning_max, self.v_warning_min, self.v_warning_max
        )


class TargetKind(Enum):
    STOP = "stop"
    """End of authority / supervised location: the EBD reaches 0 at the target."""
    SPEED = "speed"
    """MRSP decrease: the EBD reaches V_target + dV_ebi(V_target) at the target (§3.13.8.3)."""


@dataclass(frozen=True)
class Target:
    location: float
    speed: float = 0.0
    kind: TargetKind = TargetKind.STOP

    def foot_speed(self, fixed: FixedValues) -> float:
        if self.kind is TargetKind.SPEED:
            return self.speed + fixed.dv_ebi(self.speed)
        return self.speed


@dataclass(frozen=True)
class CurveTimes:
    """The time offsets between the curves (§3.13.9.3), for one train."""

    t_be: float
    """Equivalent emergency brake build-up time, s."""
    t_bs: float
    """Equivalent service brake build-up time, s."""
    service_brake_command: bool = False
    """True if the ATP can command the service brake (then T_bs2 = T_bs, else 0)."""
    t_traction: float = 0.0
    """Time from the EBI being passed until traction is cut (cut-off time + ATP cycle), s."""
    a_est_cap: float = math.inf
    """Upper bound on the estimated acceleration in V_delta1/V_delta2 (none by default: the
    train's real acceleration is used, which is safe for any traction)."""
    fixed: FixedValues = field(default_factory=FixedValues)

    @property
    def t_berem(self) -> float:
        return max(self.t_be - self.t_traction, 0.0)

    @property
    def t_bs2(self) -> float:
        return self.t_bs if self.service_brake_command else 0.0

    @property
    def t_indication(self) -> float:
        """Indication lead over the permitted curve: max(0.8·T_bs, 5 s)."""
        return max(0.8 * self.t_bs, 5.0)

    def bec(self, v: float, v_target: float = 0.0, a_est: float = 0.0) -> tuple[float, float]:
        """(V_bec, D_bec) for a train at speed v accelerating at a_est (§3.13.9.3.2)."""
        t_tr = self.t_traction
        t_rem = self.t_be - t_tr if self.t_be > t_tr else 0.0
        if a_est <= 0.0 and v >= v_target:  # the common case, kept cheap for the ATP cycle
            return v, v * (t_tr + t_rem)
        a = max(0.0, min(a_est, self.a_est_cap))
        dv1 = a * t_tr
        dv2 = a * t_rem
        v_bec = max(v + dv1, v_target) + dv2
        d_bec = (
            max(v + dv1 / 2.0, v_target) * self.t_traction
            + (max(v + dv1, v_target) + dv2 / 2.0) * self.t_berem
        )
        return v_bec, d_bec


# --------------------------------------------------------------------------- exact, one target


def _integrate(
    decel: SafeDeceleration, x: float, v: float, v_goal: float, x_breaks: list[float]
) -> float:
    """Location where a braking curve through (x, v) reaches v_goal; exact for step models."""
    brake = decel.brake
    if v_goal >= v:  # walk backwards (speed rises as we go away from the target)
        while v < v_goal - _EPS:
            a = decel.at(v + _EPS, x - _EPS)
            if a <= 0:
                raise UsageError(f"no positive safe deceleration at x={x:.1f} m, v={v:.2f} m/s")
            xb = max((b for b in x_breaks if b < x - _EPS), default=-math.inf)
            v_next = min(v_goal, brake.next_step_above(v + _EPS))
            dx = (v_next * v_next - v * v) / (2.0 * a)
            if x - dx >= xb:
                x, v = x - dx, v_next
            else:
                v = math.sqrt(v * v + 2.0 * a * (x - xb))
                x = xb
        return x
    while v > v_goal + _EPS:  # walk forwards past the foot (negative distances before target)
        a = decel.at(v - _EPS, x + _EPS)
        if a <= 0:
            raise UsageError(f"no positive safe deceleration at x={x:.1f} m, v={v:.2f} m/s")
        xb = min((b for b in x_breaks if b > x + _EPS), default=math.inf)
        lower = [s for s in brake.steps if s < v - _EPS]
        v_next = max(v_goal, lower[-1] if lower else 0.0)
        dx = (v * v - v_next * v_next) / (2.0 * a)
        if x + dx <= xb:
            x, v = x + dx, v_next
        else:
            v = math.sqrt(max(v * v - 2.0 * a * (xb - x), 0.0))
            x = xb
    return x


def ebd_distance(
    decel: SafeDeceleration, target: Target, v: float, fixed: FixedValues | None = None
) -> float:
    """Distance before the target (m) at which the EBD towards it equals speed v (m/s)."""
    fixed = fixed or FixedValues()
    breaks = sorted(decel.gradient.breakpoints())
    x = _integrate(decel, target.location, target.foot_speed(fixed), v, breaks)
    return target.location - x


@dataclass(frozen=True)
class CurveDistances:
    """Distances before a target at which each curve reaches one train speed."""

    ebd: float
    ebi: float
    sbi2: float
    warning: float
    permitted: float
    indication: float


def _sbi2_distance(
    decel: SafeDeceleration, target: Target, times: CurveTimes, v: float, a_est: float
) -> tuple[float, float]:
    v_bec, d_bec = times.bec(v, target.speed, a_est)
    ebi = ebd_distance(decel, target, v_bec, times.fixed) + d_bec
    return ebi, ebi + v * times.t_bs2


def curve_distances(
    decel: SafeDeceleration,
    target: Target,
    times: CurveTimes,
    v: float,
    a_est: float = 0.0,
    v_mrsp: float = math.inf,
) -> CurveDistances:
    """Every target-speed-monitoring curve at train speed v, as distance before the target.

    The indication point is where braking should begin to meet the target from the permitted
    speed, so above the MRSP ahead of the target it is taken at V_MRSP (a train is never
    permitted faster).
    """
    fixed = times.fixed
    ebd = ebd_distance(decel, target, v, fixed)
    ebi, sbi2 = _sbi2_distance(decel, target, times, v, a_est)
    warning = sbi2 + v * fixed.t_warning
    permitted = sbi2 + v * fixed.t_driver
    if target.kind is TargetKind.SPEED and v <= target.speed:
        permitted = 0.0  # at or below V_target the permitted speed is the MRSP step itself
    v_i = min(v, v_mrsp)
    sbi2_i = sbi2 if v_i == v else _sbi2_distance(decel, target, times, v_i, a_est)[1]
    indication = sbi2_i + v_i * (fixed.t_driver + times.t_indication)
    return CurveDistances(ebd, ebi, sbi2, warning, permitted, indication)


# --------------------------------------------------------------------------- grid, many targets


@dataclass
class Grid:
    """A location grid with the cumulative gradient acceleration precomputed (rebuild on change)."""

    x: FloatArray
    decel: SafeDeceleration
    h: FloatArray = field(init=False)
    """h[i] = ∫_x0^x_i A_gradient dx (midpoint rule per cell)."""

    def __post_init__(self) -> None:
        mids = 0.5 * (self.x[1:] + self.x[:-1])
        ag = self.decel.gradient_accel_grid(mids)
        self.h = np.concatenate(([0.0], np.cumsum(ag * np.diff(self.x))))
        self.a_min = min(self.decel.brake.values) + (float(ag.min()) if ag.size else 0.0)
        """Lowest safe deceleration anywhere: bounds how far back a curve can stay below a cap."""

    @classmethod
    def uniform(cls, start: float, stop: float, step: float, decel: SafeDeceleration) -> Grid:
        n = int(math.ceil((stop - start) / step)) + 1
        return cls(start + step * np.arange(n, dtype=np.float64), decel)


def ebd_on_grid(
    grid: Grid, target: Target, fixed: FixedValues, v_cap: float, x_from: float = -math.inf
) -> FloatArray:
    """EBD speed (m/s) at every grid location towards one target; inf beyond the target.

    For a STOP target the speed beyond it is 0 (no movement past it is allowed). Computation stops
    once the curve exceeds v_cap (the rest is set to inf): nothing above it is ever supervised.
    Locations before `x_from` are left at inf (not computed): the ATP only looks ahead.
    """
    x = grid.x
    out = np.full(x.shape, np.inf)
    k = int(np.searchsorted(x, target.location, side="right"))  # x[:k] <= target
    if target.kind is TargetKind.STOP:
        out[k:] = 0.0
    if k == 0:
        return out
    brake = grid.decel.brake
    h_t = float(np.interp(target.location, x, grid.h))
    xs, hs = target.location, h_t
    v2s = target.foot_speed(fixed) ** 2
    hi = k  # x[lo:hi] still to fill
    if grid.a_min > 0.0 and math.isfinite(v_cap):
        reach = (v_cap * v_cap - target.foot_speed(fixed) ** 2) / (2.0 * grid.a_min)
        x_from = max(x_from, target.location - max(reach, 0.0) - 2.0)
    lo = max(int(np.searchsorted(x, x_from, side="left")) - 1, 0)
    steps = list(brake.steps)
    while hi > lo:
        v_now = math.sqrt(v2s)
        a = brake(v_now + _EPS)
        # v² over the remaining slice with this band's brake deceleration
        seg_x = x[lo:hi]
        v2 = v2s + 2.0 * a * (xs - seg_x) + 2.0 * (hs - grid.h[lo:hi])
        nxt = next((s for s in steps if s > v_now + _EPS), math.inf)
        limit = min(nxt, v_cap)
        # v2 decreases with index; find the first index (from the end) where v² >= limit²
        rev = v2[::-1]
        j = int(np.searchsorted(rev, limit * limit, side="left"))  # count below limit²
        # positions hi-j .. hi-1 are within the band
        start = hi - j
        out[start:hi] = np.sqrt(np.maximum(v2[start - lo :], 0.0))
        if start == lo or not math.isfinite(limit) or limit >= v_cap:
            break
        # crossing between x[start-1] (above) and x[start] (below): interpolate in v²
        i0 = start - 1
        v2a = float(v2[i0 - lo])
        v2b = float(v2[start - lo]) if start < hi else v2s
        xb = float(x[start]) if start < hi else xs
        hb = float(grid.h[start]) if start < hi else hs
        frac = (limit * limit - v2b) / (v2a - v2b) if v2a != v2b else 0.0
        xs = xb + frac * (float(x[i0]) - xb)
        hs = hb + frac * (float(grid.h[i0]) - hb)
        v2s = limit * limit
        hi = start
    return out


def ebd_min_on_grid(
    grid: Grid, targets: list[Target], fixed: FixedValues, v_cap: float
) -> FloatArray:
    """The supervised EBD: the minimum over every target ahead (not only the next one)."""
    out = np.full(grid.x.shape, np.inf)
    for t in targets:
        np.minimum(out, ebd_on_grid(grid, t, fixed, v_cap), out=out)
    return out


@dataclass(frozen=True)
class CurveSet:
    """Speed limits (m/s) at every grid location, for display and the reports."""

    x: FloatArray
    mrsp: FloatArray
    ebd: FloatArray
    ebi: FloatArray
    sbi: FloatArray
    warning: FloatArray
    permitted: FloatArray
    indication: FloatArray


def _shifted(x: FloatArray, v: FloatArray, lead: FloatArray) -> FloatArray:
    """Speed curve whose value at location x_i - lead_i is v_i, resampled onto x (monotone)."""
    finite = np.isfinite(v)
    out = np.full(x.shape, np.inf)
    if not finite.any():
        return out
    s = x[finite] - lead[finite]
    vf = v[finite]
    # keep the monotone part (s increasing); where the target switches, s may fold back
    keep = np.concatenate(([True], np.diff(s) > 0))
    s, vf = s[keep], vf[keep]
    inside = (x >= s[0]) & (x <= s[-1])
    out[inside] = np.interp(x[inside], s, vf)
    out[x > s[-1]] = vf[-1]
    return out


def curves_on_grid(
    grid: Grid,
    targets: list[Target],
    mrsp: FloatArray,
    times: CurveTimes,
    v_cap: float,
) -> CurveSet:
    """EBD, EBI, SBI, warning, permitted and indication speeds over the grid (a_est = 0).

    Each target's curves are shifted from its own EBD (so the shifts stay monotone), then the
    minimum over targets is taken and each limit is capped by its ceiling V_MRSP + dV.
    """
    fixed = times.fixed
    x = grid.x
    inf = np.full(x.shape, np.inf)
    ebd, ebi, sbi, warn, perm, ind = (inf.copy() for _ in range(6))
    t_be = times.t_traction + times.t_berem
    leads = (
        0.0,
        times.t_bs2,
        times.t_bs2 + fixed.t_warning,
        times.t_bs2 + fixed.t_driver,
        times.t_bs2 + fixed.t_driver + times.t_indication,
    )
    outs = (ebi, sbi, warn, perm, ind)
    step = float(x[1] - x[0]) if len(x) > 1 else 1.0
    for t in targets:
        e = ebd_on_grid(grid, t, fixed, v_cap)
        np.minimum(ebd, e, out=ebd)
        k = int(np.searchsorted(x, t.location, side="right"))  # x[:k] before the target
        if t.kind is TargetKind.STOP:
            for o in outs:
                o[k:] = 0.0
        finite = np.flatnonzero(np.isfinite(e[:k]))
        if finite.size == 0:
            continue
        i0 = int(finite[0])
        # work only on the window the shifted curves can reach (leads are at most v_cap·T)
        back = int(math.ceil(v_cap * (t_be + leads[-1]) / step)) + 2
        w0 = max(i0 - back, 0)
        xs, es = x[w0:k], e[w0:k]
        v = np.where(np.isfinite(es), np.maximum(es, t.speed), es)
        for o, lead in zip(outs, leads, strict=True):
            seg = _shifted(xs, v, v * (t_be + lead))
            np.minimum(o[w0:k], seg, out=o[w0:k])
    dv_ebi = _ramp_vec(mrsp, fixed, "ebi")
    dv_sbi = _ramp_vec(mrsp, fixed, "sbi")
    dv_w = _ramp_vec(mrsp, fixed, "warning")
    return CurveSet(
        x=x,
        mrsp=mrsp,
        ebd=ebd,
        ebi=np.minimum(ebi, mrsp + dv_ebi),
        sbi=np.minimum(sbi, mrsp + dv_sbi),
        warning=np.minimum(warn, mrsp + dv_w),
        permitted=np.minimum(perm, mrsp),
        indication=np.minimum(ind, mrsp),
    )


def _ramp_vec(v: FloatArray, fixed: FixedValues, which: str) -> FloatArray:
    lo, hi, vlo, vhi = {
        "ebi": (fixed.dv_ebi_min, fixed.dv_ebi_max, fixed.v_ebi_min, fixed.v_ebi_max),
        "sbi": (fixed.dv_sbi_min, fixed.dv_sbi_max, fixed.v_sbi_min, fixed.v_sbi_max),
        "warning": (
            fixed.dv_warning_min,
            fixed.dv_warning_max,
            fixed.v_warning_min,
            fixed.v_warning_max,
        ),
    }[which]
    c = (hi - lo) / (vhi - vlo)
    out: FloatArray = np.clip(lo + c * (v - vlo), lo, hi)
    return out
