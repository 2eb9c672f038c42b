"""The assertions a scenario file may state, checked against a finished run's records.

Owns the vocabulary: `min_gap` (follower never closer than X m to the leader's rear),
`stops_at` (a train comes to a standstill within ±tolerance of a mark), `never_passes` (front
never beyond a location), `never_exceeds_ebd`, `event` (count of an event kind within bounds),
`reaches` (front reaches a location, optionally by a time) and `max_speed` (optionally only while
the front is within [from_m, to_m)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ktcs_bench import kinds
from ktcs_bench.scenario.model import Assertion
from ktcs_bench.scenario.runner import RunResult
from ktcs_bench.train.units import to_kmh


@dataclass(frozen=True)
class Outcome:
    assertion: Assertion
    passed: bool
    detail: str


def _stops(result: RunResult, train: str) -> list[tuple[float, float]]:
    """(time, front) of every transition from moving to standstill."""
    tr = result.traces[train]
    out = []
    for i in range(1, len(tr.speed)):
        if tr.speed[i] <= 0.0 < tr.speed[i - 1]:
            out.append((tr.t[i], tr.head[i]))
    return out


def check(a: Assertion, result: RunResult) -> Outcome:
    g = a.args
    tr = result.traces.get(str(g.get(kinds.TRAIN, "")))
    if a.kind == "min_gap":
        f, lead = result.traces[str(g["follower"])], result.traces[str(g["leader"])]
        gaps = [lt - fh for fh, lt in zip(f.head, lead.tail, strict=True)]
        worst = min(gaps)
        need = float(g["at_least"])
        return Outcome(a, worst >= need, f"closest gap {worst:.1f} m (must be ≥ {need} m)")
    assert tr is not None
    if a.kind == "stops_at":
        mark, tol = float(g["mark"]), float(g.get("tolerance", 0.3))
        stops = _stops(result, str(g[kinds.TRAIN]))
        if not stops:
            return Outcome(a, False, "the train never stopped")
        best = min(stops, key=lambda s: abs(s[1] - mark))
        err = best[1] - mark
        return Outcome(
            a,
            abs(err) <= tol,
            f"stopped at {best[1]:.2f} m at t={best[0]:.1f} s: {err:+.2f} m from the mark "
            f"(±{tol} m)",
        )
    if a.kind == "never_passes":
        loc = float(g["location"])
        worst = max(tr.head)
        return Outcome(a, worst <= loc, f"front reached {worst:.2f} m (limit {loc} m)")
    if a.kind == "never_exceeds_ebd":
        over = [(t, v - e) for t, v, e in zip(tr.t, tr.speed, tr.ebd_at_head, strict=True) if v > e]
        if over:
            t, d = max(over, key=lambda o: o[1])
            return Outcome(a, False, f"exceeded the EBD by {to_kmh(d):.2f} km/h at t={t:.1f} s")
        return Outcome(a, True, "speed stayed below the EBD at the true front")
    if a.kind == "event":
        kind = str(g["kind"])
        n = sum(1 for e in result.events if e.train == str(g[kinds.TRAIN]) and e.kind == kind)
        lo = int(g.get("at_least", 0 if "at_most" in g else 1))
        hi = int(g.get("at_most", 10**9))
        return Outcome(a, lo <= n <= hi, f"{n} × {kind} (wanted {lo}..{hi if hi < 10**9 else '∞'})")
    if a.kind == "reaches":
        loc = float(g["location"])
        by = float(g.get("by_s", math.inf))
        hit = next((t for t, h in zip(tr.t, tr.head, strict=True) if h >= loc), None)
        ok = hit is not None and hit <= by
        return Outcome(
            a,
            ok,
            f"reached {loc} m at t={hit:.1f} s"
            if hit is not None
            else f"never reached {loc} m (front at most {max(tr.head):.1f} m)",
        )
    if a.kind == "max_speed":
        lim = float(g["kmh"])
        start, end = float(g.get("from_m", -math.inf)), float(g.get("to_m", math.inf))
        where = "" if "from_m" not in g and "to_m" not in g else f" on [{start:g}, {end:g}) m"
        speeds = [v for x, v in zip(tr.head, tr.speed, strict=True) if start <= x < end]
        if not speeds:
            return Outcome(a, False, f"the front never was{where}")
        v = to_kmh(max(speeds))
        return Outcome(a, v <= lim + 1e-9, f"top speed{where} {v:.2f} km/h (limit {lim} km/h)")
    return Outcome(a, False, f"unknown assertion {a.kind}")


def check_all(result: RunResult) -> list[Outcome]:
    return [check(a, result) for a in result.scenario.assertions]
