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

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from ktcs_bench.errors import UsageError
from ktcs_bench.train.deceleration import FloatArray, SafeDeceleration
from ktcs_bench.train.units import G, kmh

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


def hold_speeds(target: Target, fixed: FixedValues) -> tuple[float, float, float, float, float]:
    """What each curve (EBI, SBI, warning, permitted, indication) reads at and beyond a target,
    looking ahead from before it: the new MRSP's ceiling for that curve — V + dV_ebi (the EBD's
    foot), V + dV_sbi, V + dV_warning, V, V — or 0 for a stop target."""
    if target.kind is TargetKind.STOP:
        return (0.0, 0.0, 0.0, 0.0, 0.0)
    v = target.speed
    return (v + fixed.dv_ebi(v), v + fixed.dv_sbi(v), v + fixed.dv_warning(v), v, v)


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


_FAR = 1.0e6
"""The gradient integral's table reaches this far beyond the grid and the profile (m)."""


@dataclass
class Grid:
    """A location grid with the cumulative gradient acceleration precomputed (rebuild on change).

    The gradient is a step profile, so its integral is piecewise linear with a kink at each
    gradient change: it is tabulated exactly at the breakpoints (`hp`, `hv`, reaching far beyond
    the grid) and interpolated onto the grid in one numpy pass.
    """

    x: FloatArray
    decel: SafeDeceleration
    h: FloatArray = field(init=False)
    """h[i] = ∫_x0^x_i A_gradient dx (exact)."""
    a_min: float = field(init=False)
    """Lowest safe deceleration on the grid: bounds how far back a curve can stay below a cap."""
    hp: FloatArray = field(init=False, repr=False)
    """Breakpoints of the gradient integral (increasing)."""
    hv: FloatArray = field(init=False, repr=False)
    """∫_x0^hp A_gradient dx."""
    flat: bool = field(init=False)
    """No gradient anywhere (h ≡ 0)."""

    def __post_init__(self) -> None:
        x = self.x
        x0, x1 = float(x[0]), float(x[-1])
        prof, rot = self.decel.gradient, self.decel.rotating
        bps = list(prof.breakpoints())
        pts = np.array([min([x0, *bps[:1]]) - _FAR, *bps, max([x1, *bps[-1:]]) + _FAR])
        grads = np.array([prof.default, *prof.gradients])  # from each point on
        if rot.nominal is not None:
            m = np.full_like(grads, rot.nominal)
        else:
            m = np.where(grads > 0, rot.maximum, rot.minimum)
        ags = grads * G / (1000.0 + 10.0 * m)
        hv = np.concatenate(([0.0], np.cumsum(ags * np.diff(pts))))
        i0 = int(pts.searchsorted(x0, side="right")) - 1
        i1 = max(i0, int(pts.searchsorted(x1, side="left")) - 1)
        hv -= hv[i0] + ags[i0] * (x0 - pts[i0])  # h(x0) = 0
        self.hp, self.hv = pts, hv
        self._pts, self._hv = pts.tolist(), hv.tolist()
        # h on the grid: linear per gradient segment (slope A_gradient), one pass
        counts = np.diff(
            x.searchsorted(pts[i0 + 1 : i1 + 1], side="left"), prepend=0, append=len(x)
        )
        seg = slice(i0, i1 + 1)
        self.h = np.repeat(ags[seg], counts) * x
        self.h += np.repeat(hv[seg] - ags[seg] * pts[seg], counts)
        self.a_min = min(self.decel.brake.values) + float(ags[seg].min())
        self.flat = not bool(ags.any())

    def h_at(self, x: float) -> float:
        """∫_x0^x A_gradient dx at any location (exact)."""
        pts, hv = self._pts, self._hv
        i = min(max(bisect.bisect_right(pts, x) - 1, 0), len(pts) - 2)
        return float(hv[i] + (hv[i + 1] - hv[i]) * (x - pts[i]) / (pts[i + 1] - pts[i]))

    @classmethod
    def uniform(cls, start: float, stop: float, step: float, decel: SafeDeceleration) -> Grid:
        n = int(math.ceil((stop - start) / step)) + 1
        return cls(start + step * np.arange(n, dtype=np.float64), decel)


_EMPTY: FloatArray = np.empty(0)


def ebd_segment(
    grid: Grid, target: Target, fixed: FixedValues, v_cap: float, x_from: float = -math.inf
) -> tuple[int, int, FloatArray]:
    """The EBD towards one target where it can matter, as (lo, k, speeds on x[lo:k]).

    x[:k] are the grid locations at or before the target; lo is where the curve (with the lowest
    deceleration anywhere) would pass v_cap, or `x_from`. Speeds above v_cap are inf. In closed
    form per brake-model speed band: v² is linear in distance plus the gradient integral, so each
    band is one numpy pass over the window and a search for where it leaves the band.
    """
    x = grid.x
    loc = target.location
    k = int(x.searchsorted(loc, side="right"))  # x[:k] <= target
    if k == 0:
        return 0, 0, _EMPTY
    foot = target.foot_speed(fixed)
    v2s = foot * foot
    if grid.a_min > 0.0 and math.isfinite(v_cap):
        reach = (v_cap * v_cap - v2s) / (2.0 * grid.a_min)
        x_from = max(x_from, loc - max(reach, 0.0) - 2.0)
    lo = max(int(x.searchsorted(x_from, side="left")) - 1, 0)
    if lo >= k:
        return k, k, _EMPTY
    brake = grid.decel.brake
    steps = brake.steps
    h = grid.h
    if len(steps) == 1:  # one brake band (the endpoint's case, every cycle): one pass
        v2 = loc - x[lo:k]
        v2 *= 2.0 * brake.values[0]
        v2 += v2s
        if not grid.flat:  # on a flat line the gradient term is exactly 0 and v² ≥ 0
            hterm = grid.h_at(loc) - h[lo:k]
            hterm *= 2.0
            v2 += hterm
        start = k - int(v2[::-1].searchsorted(v_cap * v_cap, side="left"))
        band = v2[start - lo :]
        if not grid.flat:
            np.maximum(band, 0.0, out=band)
        np.sqrt(band, out=band)
        v2[: start - lo] = np.inf
        return lo, k, v2
    vals = np.full(k - lo, np.inf)
    xs, hs = loc, grid.h_at(loc)
    hi = k  # x[lo:hi] still to fill
    while hi > lo:
        v_now = math.sqrt(v2s)
        a = brake(v_now + _EPS)
        # v² over the remaining slice with this band's brake deceleration
        v2 = xs - x[lo:hi]
        v2 *= 2.0 * a
        v2 += v2s
        hterm = hs - h[lo:hi]
        hterm *= 2.0
        v2 += hterm
        nxt = next((s for s in steps if s > v_now + _EPS), math.inf)
        limit = min(nxt, v_cap)
        # v2 decreases with index; count the points (from the end) below limit²
        j = int(v2[::-1].searchsorted(limit * limit, side="left"))
        start = hi - j  # positions start .. hi-1 are within the band
        v2b = float(v2[start - lo]) if start < hi else v2s
        band = v2[start - lo :]
        np.maximum(band, 0.0, out=band)
        np.sqrt(band, out=vals[start - lo : hi - lo])
        if start == lo or not math.isfinite(limit) or limit >= v_cap:
            break
        # crossing between x[start-1] (above) and x[start] (below): interpolate in v²
        i0 = start - 1
        v2a = float(v2[i0 - lo])
        xb = float(x[start]) if start < hi else xs
        hb = float(h[start]) if start < hi else hs
        frac = (limit * limit - v2b) / (v2a - v2b) if v2a != v2b else 0.0
        xs = xb + frac * (float(x[i0]) - xb)
        hs = hb + frac * (float(h[i0]) - hb)
        v2s = limit * limit
        hi = start
    return lo, k, vals


def ebd_on_grid(
    grid: Grid, target: Target, fixed: FixedValues, v_cap: float, x_from: float = -math.inf
) -> FloatArray:
    """EBD speed (m/s) at every grid location towards one target; inf beyond the target.

    For a STOP target the speed beyond it is 0 (no movement past it is allowed). Computation stops
    once the curve exceeds v_cap (the rest is set to inf): nothing above it is ever supervised.
    Locations before `x_from` are left at inf (not computed): the ATP only looks ahead.
    """
    out = np.full(grid.x.shape, np.inf)
    lo, k, vals = ebd_segment(grid, target, fixed, v_cap, x_from)
    out[lo:k] = vals
    if target.kind is TargetKind.STOP:
        out[k:] = 0.0
    return out


def ebd_envelope(
    grid: Grid, targets: list[Target], fixed: FixedValues, v_cap: float
) -> tuple[FloatArray, list[int]]:
    """The minimum EBD over every target, and the grid indices where it jumps.

    Braking curves of one train solve one equation, dv²/dx = −2·A_safe(v, x), so they never
    cross: at each location the envelope is the curve of the lowest target still ahead, and
    "lowest" is one order for the whole line. Within brake-model speed band b a curve is
    v² = C_t,b − φ_b(x), φ_b(x) = 2·a_b·x + 2·∫A_gradient (piecewise linear, tabulated exactly),
    so per target only a few numbers are needed: its constant in each band and the location
    where it leaves each band (φ_b inverted on the gradient table), all targets at once. The
    order of the targets is their constant in the top band; a sweep from the line end gives the
    owner of each stretch, and the grid is filled with (C, a) per stretch and band and evaluated
    in one numpy pass.

    A jump is where a target's own curve ends in the envelope: the first index past a visible
    SPEED target (the envelope rises to the next curve) and past the first STOP target (0 on).
    """
    x = grid.x
    n = len(x)
    out = np.full(n, np.inf)
    if not targets:
        return out, []
    brake = grid.decel.brake
    steps, values = brake.steps, brake.values
    hp = grid.hp
    phis = [2.0 * a * hp + 2.0 * grid.hv for a in values]
    if grid.a_min <= 0.0 or any(bool((np.diff(phi) <= 0.0).any()) for phi in phis):
        return _ebd_envelope_walk(grid, targets, fixed, v_cap)
    locs = np.array([t.location for t in targets])
    ks = x.searchsorted(locs, side="right")
    stop_k = min(
        (int(k) for t, k in zip(targets, ks, strict=True) if t.kind is TargetKind.STOP),
        default=n,
    )
    foots = np.array([t.foot_speed(fixed) for t in targets])
    on = (ks > 0) & (foots < v_cap)
    if not on.any():
        out[stop_k:] = 0.0
        return out, [stop_k] if stop_k < n else []
    speed = [t.kind is TargetKind.SPEED for t, o in zip(targets, on, strict=True) if o]
    kk, foots, locs = ks[on] - 1, foots[on], locs[on]
    band = np.clip(np.searchsorted(np.asarray(steps), foots + _EPS, side="right") - 1, 0, None)
    # per band: every target's constant and the grid index range of its nodes in the band
    const = np.full(kk.shape, np.inf)
    x_lo = locs.copy()  # location where the curve enters the band from below
    bands: list[tuple[float, FloatArray, list[int], list[int]]] = []
    for b, a in enumerate(values):
        v_lo = steps[b] if b > 0 else -math.inf
        if v_lo >= v_cap:
            break
        v_hi = min(steps[b + 1] if b + 1 < len(steps) else math.inf, v_cap)
        phi = phis[b]
        up = band < b
        here = band == b
        if up.any():
            const[up] = v_lo * v_lo + np.interp(x_lo[up], hp, phi)
        const[here] = foots[here] ** 2 + np.interp(locs[here], hp, phi)
        x_hi = (
            np.interp(const - v_hi * v_hi, phi, hp)
            if math.isfinite(v_hi)
            else np.full(kk.shape, -np.inf)
        )
        active = band <= b
        i_from = np.where(active, x.searchsorted(x_hi, side="right"), 0).tolist()
        i_to = np.where(active, x.searchsorted(x_lo, side="right"), 0).tolist()
        bands.append((2.0 * a, const.copy(), i_from, i_to))
        x_lo = np.where(active, x_hi, x_lo)
    key = bands[-1][1].tolist()  # constants in the top band: the order of the curves
    # owner of each stretch of nodes: sweep from the line end over the targets' last nodes
    order = sorted(range(len(key)), key=lambda i: -int(kk[i]))
    kk_l = kk.tolist()
    c_grid = np.full(n, np.inf)
    a_grid = np.zeros(n)
    visible = [False] * len(key)
    best, best_key = -1, math.inf
    pos = 0
    while pos < len(order):
        level = kk_l[order[pos]]
        while pos < len(order) and kk_l[order[pos]] == level:
            i = order[pos]
            if key[i] < best_key:
                best, best_key = i, key[i]
            pos += 1
        nxt = kk_l[order[pos]] if pos < len(order) else -1
        visible[best] = visible[best] or best_key == key[best] and level == kk_l[best]
        lo_i, hi_i = nxt + 1, level + 1  # nodes owned by `best`
        for a2, cst, i_from, i_to in bands:
            f, t = max(i_from[best], lo_i), min(i_to[best], hi_i)
            if t > f:
                c_grid[f:t] = cst[best]
                a_grid[f:t] = a2
    v2 = a_grid * x
    v2 += grid.h
    v2 += grid.h
    np.subtract(c_grid, v2, out=v2)
    np.maximum(v2, 0.0, out=v2)
    np.sqrt(v2, out=out)
    out[stop_k:] = 0.0
    breaks = {kk_l[i] + 1 for i, vis in enumerate(visible) if vis and speed[i]}
    breaks = {k for k in breaks if k < stop_k}
    if stop_k < n:
        breaks.add(stop_k)
    return out, sorted(breaks)


def _ebd_envelope_walk(
    grid: Grid, targets: list[Target], fixed: FixedValues, v_cap: float
) -> tuple[FloatArray, list[int]]:
    """`ebd_envelope` target by target (for gradients steeper than the brake)."""
    n = len(grid.x)
    out = np.full(n, np.inf)
    stop_k = n
    ends: list[tuple[int, float]] = []
    for t in targets:
        lo, k, vals = ebd_segment(grid, t, fixed, v_cap)
        if k > lo:
            seg = out[lo:k]
            np.minimum(seg, vals, out=seg)
            ends.append((k, float(vals[-1])))
        if t.kind is TargetKind.STOP:
            stop_k = min(stop_k, k)
    out[stop_k:] = 0.0
    breaks = {k for k, last in ends if k < stop_k and math.isfinite(last) and out[k - 1] == last}
    if stop_k < n:
        breaks.add(stop_k)
    return out, sorted(breaks)


def ebd_min_on_grid(
    grid: Grid, targets: list[Target], fixed: FixedValues, v_cap: float
) -> FloatArray:
    """The supervised EBD: the minimum over every target ahead (not only the next one)."""
    return ebd_envelope(grid, targets, fixed, v_cap)[0]


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


class _EnvelopeShift:
    """Curves that lie a speed-dependent distance v·T before the EBD envelope, on the same grid.

    A train at s with speed v is beyond such a curve when v > EBD(s + v·T); for one target that
    curve is its EBD point (x, v) moved to s = x − v·T, which is monotone in x. The minimum over
    targets of those shifted curves is the same shift applied to the envelope piece by piece:
    the envelope splits into runs (one per visible target: cut where it jumps, where it is
    infinite, or if it ever folds back), each run is resampled onto the grid with one `np.interp`
    (held at its last speed up to its end location) and the runs' minimum is taken.
    """

    def __init__(self, x: FloatArray, ebd: FloatArray, breaks: list[int]) -> None:
        self.x, self.ebd = x, ebd
        fin = np.isfinite(ebd)
        self.both = fin[1:] & fin[:-1]  # pairs of neighbours inside one run
        for k in breaks:
            if 0 < k < len(x):
                self.both[k - 1] = False
        edges = np.flatnonzero(fin[1:] != fin[:-1]) + 1
        bounds = [0, *edges.tolist(), len(x)]
        runs: list[tuple[int, int]] = []
        first_finite = bool(fin[0]) if len(x) else False
        for i, (a, b) in enumerate(zip(bounds, bounds[1:], strict=False)):
            if (i % 2 == 0) == first_finite:
                cuts = [k for k in breaks if a < k < b]
                runs.extend(zip([a, *cuts], [*cuts, b], strict=True))
        self.runs = runs
        # a run whose EBD never rises cannot fold back, whatever the lead (x rises strictly)
        with np.errstate(invalid="ignore"):
            self.may_fold = bool((self.both & (ebd[1:] > ebd[:-1])).any())

    def __call__(self, lead_time: float) -> FloatArray:
        x, ebd = self.x, self.ebd
        out = np.full(x.shape, np.inf)
        if not self.runs:
            return out
        with np.errstate(invalid="ignore"):
            s = x - ebd * lead_time
        runs = self.runs
        folds: list[int] = []
        if self.may_fold:
            folds = (np.flatnonzero((s[1:] <= s[:-1]) & self.both) + 1).tolist()
        if folds:  # never for an envelope of braking curves; kept for odd ones
            cut = sorted({*(a for a, _ in runs), *folds})
            runs = [
                (c, min(nb, b))
                for a, b in runs
                for c, nb in zip(
                    [c for c in cut if a <= c < b], [*(c for c in cut if a < c < b), b], strict=True
                )
            ]
        firsts = x.searchsorted(s[[a for a, _ in runs]], side="left").tolist()
        for (a, b), ja in zip(runs, firsts, strict=True):
            vals = np.interp(x[ja:b], s[a:b], ebd[a:b])
            seg = out[ja:b]
            np.minimum(seg, vals, out=seg)
        return out


def _leads(times: CurveTimes) -> list[float]:
    """T_be + the lead of EBI, SBI, warning, permitted and indication (§3.13.9.3)."""
    fixed = times.fixed
    t_be = times.t_traction + times.t_berem
    return [
        t_be + lead
        for lead in (
            0.0,
            times.t_bs2,
            times.t_bs2 + fixed.t_warning,
            times.t_bs2 + fixed.t_driver,
            times.t_bs2 + fixed.t_driver + times.t_indication,
        )
    ]


def _ceilings(mrsp: FloatArray, fixed: FixedValues) -> list[FloatArray]:
    """V_MRSP + dV for EBI, SBI and warning, V_MRSP for permitted and indication. The MRSP is a
    step profile, so dV is formed per step and repeated."""
    starts = np.concatenate(([0], np.flatnonzero(mrsp[1:] != mrsp[:-1]) + 1))
    counts = np.diff(starts, append=len(mrsp))
    steps = mrsp[starts]
    out = [np.repeat(steps + _ramp_vec(steps, fixed, w), counts) for w in ("ebi", "sbi", "warning")]
    return [*out, mrsp, mrsp]


def curves_on_grid(
    grid: Grid,
    targets: list[Target],
    mrsp: FloatArray,
    times: CurveTimes,
    v_cap: float,
) -> CurveSet:
    """EBD, EBI, SBI, warning, permitted and indication speeds over the grid (a_est = 0).

    The EBD is the minimum over every target; the other curves are that envelope shifted by
    v·(T_be + lead) (`_EnvelopeShift`), each capped by its ceiling V_MRSP + dV.
    """
    ebd, breaks = ebd_envelope(grid, targets, times.fixed, v_cap)
    return curves_from_envelope(grid.x, ebd, breaks, targets, mrsp, times)


def curves_from_envelope(
    x: FloatArray,
    ebd: FloatArray,
    breaks: list[int],
    targets: Sequence[Target],
    mrsp: FloatArray,
    times: CurveTimes,
) -> CurveSet:
    """The curve set of an EBD envelope already built on grid `x` from `targets` (`breaks`: the
    grid indices where it jumps, `ebd_envelope`): each curve the envelope shifted by
    v·(T_be + lead), no higher than each target's hold for it beyond the target
    (`_hold_at_targets`), capped by its ceiling."""
    shift = _EnvelopeShift(x, ebd, breaks)
    leads = _leads(times)
    curves = [shift(t) for t in leads]
    ceilings = _ceilings(mrsp, times.fixed)
    tops = [float(c.max()) if len(c) else 0.0 for c in ceilings]
    _hold_at_targets(x, ebd, curves, tops, leads, targets, times.fixed)
    for curve, ceiling in zip(curves, ceilings, strict=True):
        np.minimum(curve, ceiling, out=curve)
    ebi, sbi, warn, perm, ind = curves
    return CurveSet(x, mrsp, ebd, ebi, sbi, warn, perm, ind)


def _hold_at_targets(
    x: FloatArray,
    ebd: FloatArray,
    curves: list[FloatArray],
    tops: list[float],
    leads: list[float],
    targets: Sequence[Target],
    fixed: FixedValues,
    start: int = 0,
) -> None:
    """Beyond a target each curve reads the target's hold for it (`hold_speeds`), so at s
    before the target a curve with total lead T is no higher than max(hold, (L − s)/T): any
    faster and its look-ahead passes L. Applied in place from node `start` on, where it can
    bind: a shifted curve whose look-ahead passes L is already no higher than the EBD there
    (at most `ebd` at the last node before L), nor than its top speed `tops`."""
    n = len(x)
    for t in targets:
        loc = t.location
        if not math.isfinite(loc):
            continue
        hi = int(x.searchsorted(loc, side="left"))  # nodes before the target
        k = int(x.searchsorted(loc, side="right"))
        left = float(ebd[k - 1]) if 0 < k <= n else math.inf
        for curve, top, lead, hold in zip(curves, tops, leads, hold_speeds(t, fixed), strict=True):
            reach = min(top, left)
            if lead <= 0.0 or hold >= reach:
                continue
            lo = max(int(x.searchsorted(loc - reach * lead, side="left")), start)
            if hi > lo:
                seg = curve[lo:hi]
                np.minimum(seg, np.maximum((loc - x[lo:hi]) / lead, hold), out=seg)


class CurveBuilder:
    """One train's full curve set, rebuilt every cycle for its moving stop target (EoA).

    What does not move is built once: the grid, the envelope of the static (MRSP) targets, its
    shifted curves and the ceilings. An update lays the stop target's EBD over the static
    envelope on its window and recomputes the shifted curves only from where they can see that
    window: a curve at node j depends on the EBD at nodes j … j + v·T only, so nodes further back
    keep their static values. Same values as `curves_on_grid` with the stop target added (the
    stop curve is the band-walk `ebd_segment`, equal to the envelope's form to ~1e-12 on a flat
    line, to the crossing-cell interpolation with gradients).
    """

    def __init__(
        self,
        grid: Grid,
        static_targets: list[Target],
        mrsp: FloatArray,
        times: CurveTimes,
        v_cap: float,
    ) -> None:
        self.grid, self.mrsp, self.times, self.v_cap = grid, mrsp, times, v_cap
        self._targets = list(static_targets)
        self._static, self._breaks = ebd_envelope(grid, static_targets, times.fixed, v_cap)
        self._leads = _leads(times)
        self._ceilings = _ceilings(mrsp, times.fixed)
        self._tops = [float(c.max()) if len(c) else 0.0 for c in self._ceilings]
        shift = _EnvelopeShift(grid.x, self._static, self._breaks)
        self._curves = [shift(t) for t in self._leads]
        _hold_at_targets(
            grid.x, self._static, self._curves, self._tops, self._leads, static_targets, times.fixed
        )
        for curve, ceiling in zip(self._curves, self._ceilings, strict=True):
            np.minimum(curve, ceiling, out=curve)
        step = float(grid.x[1] - grid.x[0]) if len(grid.x) > 1 else 1.0
        top = max(self._leads) * v_cap if math.isfinite(v_cap) else math.inf
        self._reach = int(math.ceil(top / step)) + 2 if math.isfinite(top) else len(grid.x)

    def update(self, stop: float) -> CurveSet:
        """The curve set with the stop target (EoA) at `stop`."""
        x, n = self.grid.x, len(self.grid.x)
        lo, k, vals = ebd_segment(self.grid, Target(stop), self.times.fixed, self.v_cap)
        static = self._static
        ebd = static.copy()
        np.minimum(static[lo:k], vals, out=ebd[lo:k])
        ebd[k:] = 0.0
        breaks = [b for b in self._breaks if b < k and ebd[b - 1] == static[b - 1]]
        if k < n:
            breaks.append(k)
        w = max(min(lo, k) - self._reach, 0)
        shift = _EnvelopeShift(x[w:], ebd[w:], [b - w for b in breaks if b > w])
        curves = []
        for cached, lead in zip(self._curves, self._leads, strict=True):
            curve = cached.copy()
            curve[w:] = shift(lead)
            curves.append(curve)
        targets = [t for t in self._targets if t.location > x[w]] + [Target(stop)]
        _hold_at_targets(x, ebd, curves, self._tops, self._leads, targets, self.times.fixed, w)
        for curve, ceiling in zip(curves, self._ceilings, strict=True):
            np.minimum(curve[w:], ceiling[w:], out=curve[w:])
        ebi, sbi, warn, perm, ind = curves
        return CurveSet(x, self.mrsp, ebd, ebi, sbi, warn, perm, ind)


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
