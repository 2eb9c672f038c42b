"""Speed and distance supervision (seed 001 §2.4.3, Subset-026 §3.13.10).

Owns the verdict of one ATP cycle: given the train's (max-safe) front location, its speed and
acceleration, the supervised EBD (a speed per location of the curve grid) and the MRSP, decide the
status — normal, indication, overspeed, warning, intervention — and the commands: traction cut,
service brake, emergency brake. The emergency brake, once commanded, stays latched until the train
is at standstill *and* `release()` is called. The service brake is released when the speed is
back at or below the permitted speed.

Target limits are checked the Subset-026 way, without building every curve: the train is past the
EBI when V_bec exceeds the EBD at the location it will have reached after D_bec, and similarly for
SBI2/warning/permitted/indication with their extra time offsets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from ktcs_bench.train.curves import CurveTimes
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
class Verdict:
    status: Status
    traction_cut: bool
    service_brake: bool
    emergency_brake: bool
    permitted: float
    """Permitted speed at the train's location (m/s), for the driver/ATO."""
    reason: str = ""


@dataclass
class SupervisionLimits:
    """The curve grid the supervisor reads: location grid, EBD speed and MRSP speed on it."""

    x: FloatArray
    ebd: FloatArray
    mrsp: FloatArray

    def __post_init__(self) -> None:
        self._x0 = float(self.x[0])
        self._step = float(self.x[1] - self.x[0]) if len(self.x) > 1 else 1.0
        self._n = len(self.x)

    def _index(self, x: float) -> tuple[int, float]:
        f = (x - self._x0) / self._step
        if f <= 0.0:
            return 0, 0.0
        i = int(f)
        if i >= self._n - 1:
            return self._n - 1, 0.0
        return i, f - i

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
        self.last: Verdict | None = None
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
        self.last = Verdict(Status.INTERVENTION, True, False, True, 0.0, reason)

    def _limit_speed(
        self, lim: SupervisionLimits, x: float, v: float, lead: float, a: float
    ) -> bool:
        """True when the train at (x, v) is beyond the target curve offset by `lead` seconds."""
        if a <= 0.0 and v >= 0.0:  # `CurveTimes.bec` at a_est = 0, inlined
            return v > lim.ebd_at(x + v * self._t_bec + v * lead)
        v_bec, d_bec = self.times.bec(v, 0.0, a)
        return v_bec > lim.ebd_at(x + d_bec + v * lead)

    def check(self, lim: SupervisionLimits, x: float, v: float, a: float = 0.0) -> Verdict:
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
        ebd_at = lim.ebd_at
        past_ebi = v > c_ebi or v_bec > ebd_at(x_bec + v * l_ebi)
        past_sbi = v > c_sbi or v_bec > ebd_at(x_bec + v * l_sbi)
        past_w = v > c_w or v_bec > ebd_at(x_bec + v * l_w)
        past_p = v > v_mrsp or v_bec > ebd_at(x_bec + v * l_p)
        past_i = v_bec > ebd_at(x_bec + v * l_i)
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
        verdict = Verdict(
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
        return self.limit_speed(lim, x, lim.mrsp_at(x), self._leads[3], 18)

    def limit_speed(
        self, lim: SupervisionLimits, x: float, hi: float, lead: float, iterations: int
    ) -> float:
        """Highest v ≤ hi not beyond the curve `lead` seconds before the EBD at x (a_est = 0):
        hi itself if it is not beyond, else a bisection of `iterations` halvings from [0, hi].

        The driver and ATO ask this twice a cycle, so it is the bisection of `_limit_speed`
        with `ebd_at` inlined, plus one shortcut that keeps the result bit for bit: once both
        ends of the bracket look ahead into the same grid cell, "beyond" is linear in v there,
        so each remaining halving is decided by comparing with that cell's root (a point within
        `_GUARD` of the root is still evaluated in full).
        """
        t_bec = self._t_bec
        if not hi > lim.ebd_at(x + hi * t_bec + hi * lead):
            return hi  # the common case far from any target: one look-up
        item = lim.ebd.item
        x0, step, last = lim._x0, lim._step, lim._n - 1
        inf = math.inf
        lo = 0.0
        cell, ea, eb = -1, inf, inf  # the grid cell last read
        f = (x - x0) / step
        cell_lo = -1 if f <= 0.0 else min(int(f), last)
        f = (x + hi * t_bec + hi * lead - x0) / step
        cell_hi = -1 if f <= 0.0 else min(int(f), last)
        root, rising, fast = 0.0, True, False
        t_all = t_bec + lead
        done = 0
        while done < iterations and not fast:  # full look-ups until the bracket is in one cell
            v = 0.5 * (lo + hi)
            done += 1
            f = (x + v * t_bec + v * lead - x0) / step
            if f <= 0.0:
                e: float = item(0)
                i = -1
            else:
                i = int(f)
                if i >= last:
                    e = item(last)
                    i = last
                else:
                    if i != cell:
                        cell, ea, eb = i, item(i), item(i + 1)
                    frac = f - i
                    if frac == 0.0:
                        e = ea
                    elif ea == inf or eb == inf:
                        e = min(ea, eb)
                    else:
                        e = ea + (eb - ea) * frac
            if v > e:
                hi, cell_hi = v, i
            else:
                lo, cell_lo = v, i
            if cell_lo == cell_hi == cell and 0 <= cell < last and ea != inf and eb != inf:
                d = eb - ea
                slope = 1.0 - d * t_all / step
                if abs(slope) > 1e-3:
                    root = (ea + d * ((x - x0) / step - cell)) / slope
                    rising, fast = slope > 0.0, True
        ebd_at = lim.ebd_at
        while done < iterations:  # "beyond" is v > root (or < when falling); close to it: look
            v = 0.5 * (lo + hi)
            done += 1
            if v - root > _GUARD:
                beyond = rising
            elif root - v > _GUARD:
                beyond = not rising
            else:
                beyond = v > ebd_at(x + v * t_bec + v * lead)
            if beyond:
                hi = v
            else:
                lo = v
        return lo
