"""Speed and distance supervision (seed 001 §2.4.3, Subset-026 §3.13.10).

Owns the verdict of one ATP cycle: given the train's (max-safe) front location, its speed and
acceleration, the supervised EBD (a speed per location of the curve grid) and the MRSP, decide the
status — normal, indication, overspeed, warning, intervention — and the commands: traction cut,
service brake, emergency brake. The emergency brake, once commanded, stays latched until the train
is at standstill *and* `release()` is called. The service brake is released when the speed is
back at or below the permitted speed.

Target limits are checked the Subset-026 way, without building every curve: the train is past the
EBI when V_bec exceeds the EBD at the location it will have reached after D_bec, and similarly for
SBI2/warning/permitted/indication with their extra time offsets. A look-ahead that passes a target
reads, for each curve, that curve's ceiling of the new MRSP there (`SupervisionLimits.seen`), never
the higher curve of the next target behind the jump: so the curves keep their order at every place.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

from ktcs_bench.train.curves import CurveTimes, FixedValues, Target, TargetKind, hold_speeds
from ktcs_bench.train.deceleration import FloatArray

_GUARD = 1e-7
"""m/s: bisection points this close to a cell's root are evaluated in full, not by the root."""


class Status(Enum):
    NORMAL = "normal"
    INDICATION = "indication"
    OVERSPEED = "overspeed"
    WARNING = "warning"
    INTERVENTION = "intervention"


@dataclass(frozen=True)
class SupervisionVerdict:
    status: Status
    traction_cut: bool
    service_brake: bool
    emergency_brake: bool
    permitted: float
    """Permitted speed at the train's location (m/s), for the driver/ATO."""
    reason: str = ""


EBI, SBI, WARNING, PERMITTED, INDICATION = range(5)
"""The supervised curves, in order of their lead over the EBD (`Supervisor.curve_lead`)."""


@dataclass
class SupervisionLimits:
    """The curve grid the supervisor reads: location grid, EBD speed and MRSP speed on it, and
    the targets the EBD is built from.

    The EBD array is the envelope of every target's curve (the lowest curve still ahead at each
    place), so it jumps up just past a speed target. A look-ahead must not see past a target
    between the train and the place it looks at: curve c seen from front x at y is

        F_c(x, y) = min(EBD(y), min{hold_c(t) : x < L_t < y})

    (`seen`): beyond its location each target holds every curve at that curve's ceiling of the
    new MRSP (`hold_speeds`; 0 for a stop). F_c(x, ·) never rises, so "beyond" is monotone in
    speed, and a curve with a longer lead and a lower hold lies below (permitted ≤ warning ≤
    SBI ≤ EBI); the permitted curve comes down to V_target at a speed target. A target strictly
    inside a grid cell makes that cell's left part interpolate to the target's foot at its
    location (and its right part read the next node), so `ebd_at` never reads a jump as a ramp.
    """

    x: FloatArray
    ebd: FloatArray
    mrsp: FloatArray
    static_targets: Sequence[Target] = ()
    """Targets that stay (the MRSP's); `set_moving` lays the others over them."""
    fixed: FixedValues = field(default_factory=FixedValues)

    def __post_init__(self) -> None:
        self._x0 = float(self.x[0])
        self._step = float(self.x[1] - self.x[0]) if len(self.x) > 1 else 1.0
        self._n = len(self.x)
        ts = sorted(
            (t for t in self.static_targets if math.isfinite(t.location)),
            key=lambda t: t.location,
        )
        self._static = ts
        self._static_locs = [t.location for t in ts]
        holds = [hold_speeds(t, self.fixed) for t in ts]
        self._static_holds = [[h[c] for h in holds] for c in range(5)]
        self._static_cells: dict[int, tuple[float, float]] = {}
        for t, h in zip(ts, holds, strict=True):
            self._add_cell(self._static_cells, t.location, h[EBI])
        self.set_moving(())

    def _add_cell(self, cells: dict[int, tuple[float, float]], loc: float, foot: float) -> None:
        f = (loc - self._x0) / self._step
        if not 0.0 < f < self._n - 1:
            return
        i = int(f)
        if f > i:
            first = cells.get(i)
            cells[i] = (loc, foot) if first is None else (min(first[0], loc), min(first[1], foot))

    def set_moving(self, targets: Sequence[Target]) -> None:
        """The targets laid over the static ones now (stop target, kTCS code targets).

        A stop target only marks its grid cell: past the nearest stop the EBD itself is 0, so
        no look-ahead needs its hold."""
        self._moving = targets
        self._locs = self._static_locs
        self._holds = self._static_holds
        cells = self._cells = self._static_cells.copy()
        speed = []
        for t in targets:
            if t.kind is TargetKind.STOP:
                self._add_cell(cells, t.location, 0.0)
            elif math.isfinite(t.location):
                speed.append(t)
        if not speed:
            return
        locs = self._locs = list(self._static_locs)
        holds = self._holds = [list(h) for h in self._static_holds]
        for t in speed:
            h = hold_speeds(t, self.fixed)
            i = bisect.bisect_right(locs, t.location)
            locs.insert(i, t.location)
            for c in range(5):
                holds[c].insert(i, h[c])
            self._add_cell(cells, t.location, h[EBI])

    @property
    def targets(self) -> tuple[Target, ...]:
        """Every target the EBD is built from, static and moving, by location."""
        moving = [t for t in self._moving if math.isfinite(t.location)]
        return tuple(sorted([*self._static, *moving], key=lambda t: t.location))

    def first_ahead(self, x: float) -> int:
        """Index of the first target located beyond x."""
        return bisect.bisect_right(self._locs, x)

    def seen(self, j: int, y: float, curve: int = EBI) -> float:
        """F_curve(x, y): the EBD at y seen from a front x whose first target ahead is `j`
        (`first_ahead(x)`): no higher than the hold of any target in between."""
        e = self.ebd_at(y)
        locs, holds = self._locs, self._holds[curve]
        while j < len(locs) and locs[j] < y:
            if holds[j] < e:
                e = holds[j]
            j += 1
        return e

    def ebd_at(self, x: float) -> float:
        """EBD speed at x, linear between grid nodes (the grid is uniform).

        Called a few dozen times per cycle (bisections): kept to plain float arithmetic and
        `ndarray.item` (the array may be updated in place between calls).
        """
        f = (x - self._x0) / self._step
        ebd = self.ebd
        if f <= 0.0:
            return float(ebd.item(0))
        i = int(f)
        if i >= self._n - 1:
            return float(ebd.item(self._n - 1))
        a: float = ebd.item(i)
        frac = f - i
        if frac == 0.0:
            return a
        b: float = ebd.item(i + 1)
        cell = self._cells.get(i)
        if cell is not None:  # a target inside this cell: its foot at its location
            at = (cell[0] - self._x0) / self._step - i
            if frac > at:
                return b
            b = min(cell[1], b)
            frac /= at
        if a == math.inf or b == math.inf:
            return min(a, b)
        return a + (b - a) * frac

    def mrsp_at(self, x: float) -> float:
        f = (x - self._x0) / self._step
        i = 0 if f <= 0.0 else min(int(f), self._n - 1)
        return float(self.mrsp.item(i))


class Supervisor:
    """One train's supervision state: the latched emergency brake and the service brake."""

    def __init__(self, times: CurveTimes, service_brake_enabled: bool = True) -> None:
        self.times = times
        self.service_brake_enabled = service_brake_enabled
        self.eb_latched = False
        self.sb_applied = False
        self._release_requested = False
        self.last: SupervisionVerdict | None = None
        self._ceil_for = math.nan
        self._ceilings = (0.0, 0.0, 0.0)

    @property
    def times(self) -> CurveTimes:
        return self._times

    @times.setter
    def times(self, times: CurveTimes) -> None:
        self._times = times
        t_tr = times.t_traction
        self._t_bec = t_tr + (times.t_be - t_tr if times.t_be > t_tr else 0.0)
        """D_bec / V at a_est = 0: exactly the sum `CurveTimes.bec` forms."""
        f = times.fixed
        self._leads = (
            0.0,
            times.t_bs2,
            times.t_bs2 + f.t_warning,
            times.t_bs2 + f.t_driver,
            times.t_bs2 + f.t_driver + times.t_indication,
        )

    def release(self) -> None:
        """Driver's explicit release of the latched emergency brake (honoured at standstill)."""
        self._release_requested = True

    def trip(self, reason: str) -> None:
        """Command the emergency brake for a reason outside the curves (e.g. a missed tag)."""
        self.eb_latched = True
        self._release_requested = False
        self.last = SupervisionVerdict(Status.INTERVENTION, True, False, True, 0.0, reason)

    def curve_lead(self, curve: int) -> float:
        """The curve's time offset after the EBI (§3.13.9.3)."""
        return self._leads[curve]

    def look_ahead(self, curve: int) -> float:
        """Seconds at its speed a braking train looks ahead onto the EBD for `curve`: T_bec
        plus the curve's lead (a train at V is beyond the curve at x when V exceeds the EBD at
        x + V·look_ahead)."""
        return self._t_bec + self._leads[curve]

    def _limit_speed(
        self, lim: SupervisionLimits, x: float, v: float, curve: int, a: float
    ) -> bool:
        """True when the train at (x, v) is beyond `curve`."""
        j, lead = lim.first_ahead(x), self._leads[curve]
        if a <= 0.0 and v >= 0.0:  # `CurveTimes.bec` at a_est = 0, inlined
            return v > lim.seen(j, x + v * self._t_bec + v * lead, curve)
        v_bec, d_bec = self.times.bec(v, 0.0, a)
        return v_bec > lim.seen(j, x + d_bec + v * lead, curve)

    def check(
        self, lim: SupervisionLimits, x: float, v: float, a: float = 0.0
    ) -> SupervisionVerdict:
        """Supervise the train at max-safe front x with speed v and acceleration a."""
        f = self.times.fixed
        if self.eb_latched and v <= 0.0 and self._release_requested:
            self.eb_latched = False
        self._release_requested = False
        v_mrsp = lim.mrsp_at(x)
        if v_mrsp != self._ceil_for:  # V_MRSP + dV ceilings, kept while the MRSP is the same
            self._ceil_for = v_mrsp
            self._ceilings = (
                v_mrsp + f.dv_ebi(v_mrsp),
                v_mrsp + f.dv_sbi(v_mrsp),
                v_mrsp + f.dv_warning(v_mrsp),
            )
        c_ebi, c_sbi, c_w = self._ceilings
        l_ebi, l_sbi, l_w, l_p, l_i = self._leads
        # as `_limit_speed`, with (V_bec, D_bec) formed once for the five curves
        if a <= 0.0 and v >= 0.0:
            v_bec, d_bec = v, v * self._t_bec
        else:
            v_bec, d_bec = self.times.bec(v, 0.0, a)
        x_bec = x + d_bec
        locs = lim._locs
        j = bisect.bisect_right(locs, x)  # the first target ahead
        if j == len(locs) or locs[j] >= x_bec + v * l_i:  # no target within any look-ahead
            ebd_at = lim.ebd_at
            past_ebi = v > c_ebi or v_bec > ebd_at(x_bec + v * l_ebi)
            past_sbi = v > c_sbi or v_bec > ebd_at(x_bec + v * l_sbi)
            past_w = v > c_w or v_bec > ebd_at(x_bec + v * l_w)
            past_p = v > v_mrsp or v_bec > ebd_at(x_bec + v * l_p)
            past_i = v_bec > ebd_at(x_bec + v * l_i)
        else:
            seen = lim.seen
            past_ebi = v > c_ebi or v_bec > seen(j, x_bec + v * l_ebi, EBI)
            past_sbi = v > c_sbi or v_bec > seen(j, x_bec + v * l_sbi, SBI)
            past_w = v > c_w or v_bec > seen(j, x_bec + v * l_w, WARNING)
            past_p = v > v_mrsp or v_bec > seen(j, x_bec + v * l_p, PERMITTED)
            past_i = v_bec > seen(j, x_bec + v * l_i, INDICATION)
        permitted = self.permitted_speed(lim, x)
        reason = ""
        if past_ebi and v > 0:
            if not self.eb_latched:
                reason = "EBI exceeded"
            self.eb_latched = True
        if self.sb_applied and (v <= permitted or v <= 0):
            self.sb_applied = False
        if past_sbi and v > 0 and self.service_brake_enabled:
            self.sb_applied = True
        if self.eb_latched or past_ebi:
            status = Status.INTERVENTION
        elif past_sbi:
            status = Status.INTERVENTION if self.sb_applied else Status.WARNING
        elif past_w:
            status = Status.WARNING
        elif past_p:
            status = Status.OVERSPEED
        elif past_i:
            status = Status.INDICATION
        else:
            status = Status.NORMAL
        traction_cut = status in (Status.WARNING, Status.INTERVENTION) or self.sb_applied
        last = self.last
        if (  # the same verdict as last cycle (the usual case): no new object
            last is not None
            and last.status is status
            and last.permitted == permitted
            and last.traction_cut is traction_cut
            and last.service_brake is self.sb_applied
            and last.emergency_brake is self.eb_latched
            and last.reason == reason
        ):
            return last
        verdict = SupervisionVerdict(
            status=status,
            traction_cut=traction_cut,
            service_brake=self.sb_applied,
            emergency_brake=self.eb_latched,
            permitted=permitted,
            reason=reason,
        )
        self.last = verdict
        return verdict

    def permitted_speed(self, lim: SupervisionLimits, x: float) -> float:
        """Highest v that is not past the permitted curve at x (bisection; for driver and ATO)."""
        return self.limit_speed(lim, x, lim.mrsp_at(x), PERMITTED, 18)

    def limit_speed(
        self, lim: SupervisionLimits, x: float, hi: float, curve: int, iterations: int
    ) -> float:
        """Highest v ≤ hi not beyond `curve` at x (a_est = 0): hi itself if it is not beyond,
        else found by halving [0, hi] at most `iterations` times.

        The driver and ATO ask this twice a cycle. The halving of `_limit_speed` stops as soon
        as both ends of the bracket look ahead into the same grid cell with no target inside it
        and past the same targets: there "beyond" is v > m (the lowest hold passed) or v > the
        cell's linear root, so the answer is min(m, root), exact. (Where the EBD rises steeply
        inside the cell, beyond is v < root: the halving goes on, deciding by that root except
        within `_GUARD` of it.) If the bracket never gets into one piece, the bisection's lower
        end is the answer.
        """
        t_bec, lead = self._t_bec, self._leads[curve]
        locs, holds = lim._locs, lim._holds[curve]
        nt = len(locs)
        j0 = bisect.bisect_right(locs, x)  # the first target ahead
        next_loc = locs[j0] if j0 < nt else math.inf
        y_hi = x + hi * t_bec + hi * lead
        e = lim.ebd_at(y_hi)
        j_hi = j0
        while j_hi < nt and locs[j_hi] < y_hi:
            if holds[j_hi] < e:
                e = holds[j_hi]
            j_hi += 1
        if not hi > e:
            return hi  # the common case far from any target: one look-up
        item = lim.ebd.item
        x0, step, last = lim._x0, lim._step, lim._n - 1
        cells = lim._cells
        inf = math.inf
        ebd_at = lim.ebd_at
        seen = lim.seen
        lo = 0.0
        # grid cell and targets passed at each end's look-ahead
        f = (x - x0) / step
        i_lo, j_lo = (-1 if f <= 0.0 else min(int(f), last)), j0
        f = (y_hi - x0) / step
        i_hi = -1 if f <= 0.0 else min(int(f), last)
        cell, ea, eb, special = -1, inf, inf, True  # the grid cell last read (target inside?)
        root, m, rising, fast = 0.0, inf, True, False
        t_all = t_bec + lead
        done = 0
        while done < iterations and not fast:  # full look-ups until the bracket is in one piece
            v = 0.5 * (lo + hi)
            done += 1
            y = x + v * t_bec + v * lead
            f = (y - x0) / step
            if f <= 0.0:
                i, e = -1, item(0)
            elif f >= last:
                i, e = last, item(last)
            else:
                i = int(f)
                if i != cell:
                    cell, ea, eb = i, item(i), item(i + 1)
                    special = i in cells
                frac = f - i
                if frac == 0.0:
                    e = ea
                elif special:
                    e = ebd_at(y)
                elif ea == inf or eb == inf:
                    e = min(ea, eb)
                else:
                    e = ea + (eb - ea) * frac
            j = j0
            if y > next_loc:
                while j < nt and locs[j] < y:
                    if holds[j] < e:
                        e = holds[j]
                    j += 1
            if v > e:
                hi, i_hi, j_hi = v, i, j
            else:
                lo, i_lo, j_lo = v, i, j
            if i_lo == i_hi == cell and j_lo == j_hi and not special:
                if ea != inf and eb != inf:
                    d = eb - ea
                    slope = 1.0 - d * t_all / step
                    if abs(slope) > 1e-3:
                        root = (ea + d * ((x - x0) / step - i_lo)) / slope
                        m = min(holds[j0:j_lo], default=inf)
                        rising, fast = slope > 0.0, True
        if fast and rising:  # beyond is v > m or v > root: the highest speed not beyond
            return max(lo, min(hi, m, root))
        while done < iterations:  # beyond is v > m or v < root; close to either: look
            v = 0.5 * (lo + hi)
            done += 1
            if v - m > _GUARD:
                beyond = True
            elif m - v > _GUARD and v - root > _GUARD:
                beyond = rising
            elif m - v > _GUARD and root - v > _GUARD:
                beyond = not rising
            else:
                beyond = v > seen(j0, x + v * t_bec + v * lead, curve)
            if beyond:
                hi = v
            else:
                lo = v
        return lo
