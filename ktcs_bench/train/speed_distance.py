"""Speed–distance data of one train for a display: its curves (MRSP, EBI, SBI, permitted) over a
window around it and its actual point (front, speed), from a `TrainEndpoint` as it stands after
its last cycle (`TrainEndpoint.curve_set`, every target it supervises, kTCS codes included).

Pure: the web console draws it; a train process computes it for its own endpoint and sends it
over its control port. Speeds are km/h here (for display), positions metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ktcs_bench import kinds
from ktcs_bench.train.endpoint import TrainEndpoint
from ktcs_bench.train.units import to_kmh

BEHIND_M = 300.0  # window drawn behind the train's front
AHEAD_MIN_M = 1500.0  # and at least this far ahead (further when the target lies beyond)
MAX_POINTS = 400  # samples per curve sent to the page
SPEED_CAP_KMH = 400.0  # "no limit" (infinite EBD far from any target) is drawn at the top


@dataclass(frozen=True)
class SpeedDistance:
    train: str
    x: list[float]  # m
    curves: dict[str, list[float | None]]  # mrsp, ebi, sbi, permitted: km/h (None = no limit)
    front_m: float
    speed_kmh: float
    target_m: float | None
    status: str

    def to_json(self) -> dict[str, Any]:
        return {
            kinds.TRAIN: self.train,
            "x": self.x,
            "curves": self.curves,
            "front_m": self.front_m,
            "speed_kmh": self.speed_kmh,
            "target_m": self.target_m,
            "status": self.status,
        }


def _clean(values: np.ndarray[Any, Any]) -> list[float | None]:
    out: list[float | None] = []
    for v in values:
        f = float(v)
        out.append(round(to_kmh(f), 2) if math.isfinite(f) and to_kmh(f) < SPEED_CAP_KMH else None)
    return out


def endpoint_speed_distance(train_id: str, ep: TrainEndpoint) -> SpeedDistance:
    """Curves of `ep` as they stand after its last cycle, sampled around its front."""
    cs = ep.curve_set()
    front = ep.position.max_safe_front
    lo = max(float(cs.x[0]), front - BEHIND_M)
    hi = min(float(cs.x[-1]), max(front + AHEAD_MIN_M, ep.target_point + 100.0))
    idx = np.flatnonzero((cs.x >= lo) & (cs.x <= hi))
    if idx.size == 0:
        idx = np.arange(len(cs.x))
    step = max(1, int(math.ceil(idx.size / MAX_POINTS)))
    pick = idx[::step]
    curves = {
        "mrsp": _clean(cs.mrsp[pick]),
        "ebi": _clean(cs.ebi[pick]),
        "sbi": _clean(cs.sbi[pick]),
        "permitted": _clean(cs.permitted[pick]),
    }
    target = ep.target_point if math.isfinite(ep.target_point) else None
    return SpeedDistance(
        train=train_id,
        x=[round(float(v), 1) for v in cs.x[pick]],
        curves=curves,
        front_m=round(float(ep.position.head), 2),
        speed_kmh=round(to_kmh(ep.state.speed), 2),
        target_m=target,
        status=ep.status.value,
    )
