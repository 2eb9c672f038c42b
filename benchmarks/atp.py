"""ATP figures (SPEC §8): curve rebuild for a 15 km line at 1 m, and the seed 001 two-train
scenario against real time. Prints the figures; docs/atp.md quotes what it printed.

    .venv/bin/python benchmarks/atp.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

from ktcs_bench.datafiles import data_dir
from ktcs_bench.scenario.model import load_scenario
from ktcs_bench.scenario.runner import run
from ktcs_bench.train.curves import (
    CurveTimes,
    Grid,
    Target,
    TargetKind,
    curves_on_grid,
    ebd_min_on_grid,
)
from ktcs_bench.train.deceleration import GradientProfile, SafeDeceleration, StepFunction
from ktcs_bench.train.mrsp import Restriction, build_mrsp
from ktcs_bench.train.units import kmh


def bench_curves(repeats: int = 200, full: bool = True) -> tuple[float, float]:
    """Median and p95 ms per rebuild over 15 km at 1 m: every curve (EBD, EBI, SBI, W, P, I) when
    `full`, else the supervised EBD only (what the ATP cycle itself needs)."""
    rng = np.random.default_rng(1)
    locs = tuple(float(x) for x in np.sort(rng.uniform(0, 15000, 30)))
    grads = tuple(float(g) for g in rng.uniform(-15, 15, 30))
    decel = SafeDeceleration(
        StepFunction((0.0, kmh(60.0), kmh(120.0)), (1.1, 1.0, 0.9)),
        GradientProfile(locs, grads).compensated(200.0),
    )
    restr = [
        Restriction(a, a + 400.0, kmh(float(v)))
        for a, v in zip(np.arange(500, 14500, 1000), rng.uniform(40, 100, 14), strict=False)
    ]
    mrsp = build_mrsp(restr, kmh(160.0), 200.0)
    times = CurveTimes(t_be=2.0, t_bs=3.0, service_brake_command=True)
    samples = []
    for i in range(repeats):
        t0 = time.perf_counter()
        grid = Grid.uniform(0.0, 15000.0, 1.0, decel)  # gradient integral rebuilt too
        targets = mrsp.targets() + [Target(14000.0 - i, 0.0, TargetKind.STOP)]
        if full:
            curves_on_grid(grid, targets, mrsp.on_grid(grid.x), times, kmh(180.0))
        else:
            ebd_min_on_grid(grid, targets, times.fixed, kmh(180.0))
        samples.append((time.perf_counter() - t0) * 1000.0)
    samples.sort()
    return statistics.median(samples), samples[int(0.95 * len(samples)) - 1]


def bench_scenario() -> tuple[float, float]:
    scn = load_scenario(Path(data_dir("emulators")) / "scenarios" / "seed001_follower.yaml")
    t0 = time.perf_counter()
    result = run(scn)
    wall = time.perf_counter() - t0
    return result.end_time, wall


def main() -> int:
    setup = "15 km at 1 m (15 001 points), 15 MRSP targets + EoA, 30 gradient steps, 3 brake steps"
    med, p95 = bench_curves(full=False)
    print(f"supervised EBD rebuild, {setup}: median {med:.2f} ms, p95 {p95:.2f} ms (goal ≤ 5 ms)")
    med, p95 = bench_curves(full=True)
    print(
        f"all six curves (EBD, EBI, SBI, warning, permitted, indication), same line: "
        f"median {med:.2f} ms, p95 {p95:.2f} ms (goal ≤ 5 ms)"
    )
    virt, wall = bench_scenario()
    print(
        f"seed 001 two-train 15 km scenario: {virt:.0f} s virtual in {wall:.2f} s wall = "
        f"{virt / wall:.0f}× real time (goal ≥ 500×)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
