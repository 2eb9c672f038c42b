"""Seed 003's single-step speed profile (GetProfileSpeed) for its Table 3 simulation.

Owns V(d) = sqrt(2·D·d + (V_static + V_i)²) evaluated against **every** MRSP target ahead (not
only the next step), capped at V_MRSP + V_i — in SI units (the pitfall the SPEC names: km/h in this
formula makes the braking term 3.6² too small). With V_i = dV_ebi and D the safe deceleration
this is exactly our EBD towards a speed target without gradient, which `tests/train` checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ktcs_bench.train.deceleration import FloatArray
from ktcs_bench.train.units import kmh

TABLE3_SECTIONS: tuple[tuple[float, float], ...] = (
    (240.0, kmh(90.0)),
    (160.0, kmh(60.0)),
    (160.0, kmh(30.0)),
    (220.0, kmh(90.0)),
    (170.0, kmh(60.0)),
)
"""Seed 003 Table 3: (D_DTG length m, MRSP m/s) of the five sections (24000 cm … 17000 cm)."""
TABLE3_STEP = 2.5
"""D_DTG steps by 250 cm in the paper's simulation."""
D_FSB, D_EB = 0.7, 1.0
"""The bench's reference decelerations for seed 003, m/s² (the paper states none)."""
V_I_FSB, V_I_EB = kmh(5.0), kmh(7.5)


@dataclass(frozen=True)
class Profile:
    x: FloatArray
    mrsp: FloatArray
    v_fsb: FloatArray
    v_eb: FloatArray


def profile_speed(
    x: FloatArray, starts: Sequence[float], speeds: Sequence[float], d: float, v_i: float
) -> FloatArray:
    """The supervised speed at each location x for sections starting at `starts`."""
    idx = np.clip(np.searchsorted(np.asarray(starts), x, side="right") - 1, 0, len(starts) - 1)
    mrsp = np.asarray(speeds)[idx]
    out: FloatArray = mrsp + v_i
    for k in range(1, len(starts)):
        ahead = x < starts[k]
        v = np.sqrt(2.0 * d * np.maximum(starts[k] - x, 0.0) + (speeds[k] + v_i) ** 2)
        out = np.where(ahead, np.minimum(out, v), out)
    return out


def table3_profile(step: float = TABLE3_STEP) -> Profile:
    starts, speeds, pos = [], [], 0.0
    for length, v in TABLE3_SECTIONS:
        starts.append(pos)
        speeds.append(v)
        pos += length
    x = np.arange(0.0, pos + step / 2, step)
    idx = np.clip(np.searchsorted(np.asarray(starts), x, side="right") - 1, 0, len(starts) - 1)
    return Profile(
        x,
        np.asarray(speeds)[idx],
        profile_speed(x, starts, speeds, D_FSB, V_I_FSB),
        profile_speed(x, starts, speeds, D_EB, V_I_EB),
    )


def main() -> int:
    """Print the Table 3 profile every 10 m, and draw its Fig. 12 if a PNG path is given."""
    import sys

    p = table3_profile()
    print("x_m  MRSP_kmh  V_FSB_kmh  V_EB_kmh")
    for i in range(0, len(p.x), 4):
        print(
            f"{p.x[i]:6.1f} {p.mrsp[i] * 3.6:8.1f} {p.v_fsb[i] * 3.6:10.2f} {p.v_eb[i] * 3.6:9.2f}"
        )
    if len(sys.argv) > 1:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(10, 4))
        ax.plot(p.x, p.mrsp * 3.6, "k--", label="MRSP")
        ax.plot(p.x, p.v_fsb * 3.6, lw=2.2, label="FSB profile (V_i 5 km/h, 0.7 m/s²)")
        ax.plot(p.x, p.v_eb * 3.6, lw=1.2, label="EB profile (V_i 7.5 km/h, 1.0 m/s²)")
        ax.set_xlabel("absolute position (m)")
        ax.set_ylabel("speed (km/h)")
        ax.set_title("seed 003 Table 3 / Fig. 12")
        ax.legend()
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(sys.argv[1], dpi=110)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
