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
        i, _ = self._index(x)
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
        l_ebi, l_sbi, l_w, l_p, l_i = self._leads
        beyond = self._limit_speed
        past_ebi = v > v_mrsp + f.dv_ebi(v_mrsp) or beyond(lim, x, v, l_ebi, a)
        past_sbi = v > v_mrsp + f.dv_sbi(v_mrsp) or beyond(lim, x, v, l_sbi, a)
        past_w = v > v_mrsp + f.dv_warning(v_mrsp) or beyond(lim, x, v, l_w, a)
        past_p = v > v_mrsp or beyond(lim, x, v, l_p, a)
        past_i = beyond(lim, x, v, l_i, a)
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
        verdict = Verdict(
            status=status,
            traction_cut=status in (Status.WARNING, Status.INTERVENTION) or self.sb_applied,
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

        The driver and ATO ask this twice a cycle, so `_limit_speed`/`ebd_at` are inlined.
        """
        t_bec = self._t_bec
        item = lim.ebd.item
        x0, step, last = lim._x0, lim._step, lim._n - 1
        lo = 0.0
        v = hi
        for k in range(iterations + 1):
            if k:
                v = 0.5 * (lo + hi)
            f = (x + v * t_bec + v * lead - x0) / step
            if f <= 0.0:
                e: float = item(0)
            else:
                i = int(f)
                if i >= last:
                    e = item(last)
                else:
                    e = item(i)
                    frac = f - i
                    if frac != 0.0:
                        b: float = item(i + 1)
                        if e == math.inf or b == math.inf:
                            e = min(e, b)
                        else:
                            e = e + (b - e) * frac
            if v > e:
                hi = v
            elif k:
                lo = v
            else:
                return hi
        return lo
