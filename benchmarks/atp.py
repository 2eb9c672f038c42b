"""ATP figures (SPEC §8): curve rebuild for a 15 km line at 1 m, and the seed 001 two-train
scenario against real time. Prints the figures; docs/atp.md quotes what it printed.

    .venv/bin/python benchmarks/atp.py [--quick]

The development machine is a shared 2-core VM, so every figure is a median over repetitions, and
each is also given against a baseline timed in the same run, interleaved with it, so that figures
from a loaded and a quiet machine can be compared:

* curves: one plain numpy pass over the same 15 001-point grid (`np.sqrt(2·a·(x_end − x) + c)`,
  one allocation) — "= N passes" says how many such passes a rebuild costs;
* scenario: a fixed pure-Python float loop (the ATP cycle is Python-bound) — "= N loops".
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ktcs_bench.datafiles import data_dir
from ktcs_bench.scenario.model import load_scenario
from ktcs_bench.scenario.runner import run
from ktcs_bench.train.curves import (
    CurveBuilder,
    CurveTimes,
    Grid,
    Target,
    TargetKind,
    curves_on_grid,
    ebd_min_on_grid,
)
from ktcs_bench.train.deceleration import GradientProfile, SafeDeceleration, StepFunction
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import LineData, TrainConfig, TrainEndpoint
from ktcs_bench.train.mrsp import Restriction, build_mrsp
from ktcs_bench.train.units import kmh

LENGTH = 15000.0


def _line() -> tuple[SafeDeceleration, list[Restriction], GradientProfile]:
    rng = np.random.default_rng(1)
    locs = tuple(float(x) for x in np.sort(rng.uniform(0, LENGTH, 30)))
    grads = tuple(float(g) for g in rng.uniform(-15, 15, 30))
    gradient = GradientProfile(locs, grads)
    decel = SafeDeceleration(
        StepFunction((0.0, kmh(60.0), kmh(120.0)), (1.1, 1.0, 0.9)), gradient.compensated(200.0)
    )
    restr = [
        Restriction(float(a), float(a) + 400.0, kmh(float(v)))
        for a, v in zip(np.arange(500, 14500, 1000), rng.uniform(40, 100, 14), strict=False)
    ]
    return decel, restr, gradient


def _baseline_pass() -> Callable[[], object]:
    x = 1.0 * np.arange(15001, dtype=np.float64)
    return lambda: np.sqrt(2.0 * 1.1 * (LENGTH - x) + 4.0)


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _interleaved(
    work: Callable[[int], object], base: Callable[[], object], repeats: int, base_reps: int
) -> tuple[list[float], list[float]]:
    """Seconds per `work(i)` and per `base()` (best of `base_reps` calls), taken in turns."""
    w, b = [], []
    for i in range(repeats):
        b.append(min(_timed(base) for _ in range(base_reps)))
        w.append(_timed(lambda i=i: work(i)))  # type: ignore[misc]
    return w, b


def _stats(w: list[float], b: list[float]) -> str:
    ws = sorted(w)
    med = statistics.median(ws) * 1e3
    p95 = ws[max(int(0.95 * len(ws)) - 1, 0)] * 1e3
    ratio = statistics.median(x / y for x, y in zip(w, b, strict=True))
    return f"median {med:.2f} ms, p95 {p95:.2f} ms, = {ratio:.0f} numpy passes"


def bench_curves(repeats: int, full: bool) -> str:
    """Rebuild over 15 km at 1 m from scratch (grid and gradient integral too, the MRSP targets
    and a moving EoA): every curve (EBD, EBI, SBI, W, P, I, ceilings) when `full`, else the
    supervised EBD only."""
    decel, restr, _ = _line()
    mrsp = build_mrsp(restr, kmh(160.0), 200.0)
    times = CurveTimes(t_be=2.0, t_bs=3.0, service_brake_command=True)

    def work(i: int) -> object:
        grid = Grid.uniform(0.0, LENGTH, 1.0, decel)
        targets = mrsp.targets() + [Target(14000.0 - i, 0.0, TargetKind.STOP)]
        if full:
            return curves_on_grid(grid, targets, mrsp.on_grid(grid.x), times, kmh(180.0))
        return ebd_min_on_grid(grid, targets, times.fixed, kmh(180.0))

    work(0)  # warm-up
    return _stats(*_interleaved(work, _baseline_pass(), repeats, 5))


def bench_curves_cycle(repeats: int) -> str:
    """Every curve, as a cycle rebuilds them: grid, static (MRSP) envelope, its curves and the
    ceilings cached; the EoA moves (here to places spread over the whole line, so on average
    half the line lies beyond where its curve can reach back)."""
    decel, restr, _ = _line()
    mrsp = build_mrsp(restr, kmh(160.0), 200.0)
    times = CurveTimes(t_be=2.0, t_bs=3.0, service_brake_command=True)
    grid = Grid.uniform(0.0, LENGTH, 1.0, decel)
    builder = CurveBuilder(grid, mrsp.targets(), mrsp.on_grid(grid.x), times, kmh(180.0))

    def work(i: int) -> object:
        return builder.update(1000.0 + (i * 1237.3) % 13500.0)

    work(0)
    return _stats(*_interleaved(work, _baseline_pass(), repeats, 5))


def bench_cycle_update(repeats: int) -> str:
    """What the ATP cycle itself rebuilds: the static EBD is cached at start-up, each cycle only
    the moving stop target's curve is laid over it (here it moves 0.83 m a cycle, 30 km/h)."""
    _, restr, gradient = _line()
    line = LineData(LENGTH, [i * 100.0 for i in range(151)], gradient, restr)
    ep = TrainEndpoint(TrainConfig("T", TrainParams(), start=500.0), line)

    def work(i: int) -> object:
        ep._rebuild(9000.0 + 0.83 * i, None)
        return ep.limits

    work(0)
    return _stats(*_interleaved(work, _baseline_pass(), repeats, 5))


def _python_loop() -> float:
    acc = 0.0
    for i in range(20000):
        acc += (i * 0.5) ** 0.5
    return acc


def bench_scenario(repeats: int) -> str:
    scn = load_scenario(Path(data_dir("emulators")) / "scenarios" / "seed001_follower.yaml")
    speedups, ratios = [], []
    virt = 0.0
    for _ in range(repeats):
        base = min(_timed(_python_loop) for _ in range(5))
        t0 = time.perf_counter()
        result = run(scn)
        wall = time.perf_counter() - t0
        virt = result.end_time
        speedups.append(virt / wall)
        ratios.append(wall / base)
    lo, hi = min(speedups), max(speedups)
    return (
        f"{virt:.0f} s virtual, {repeats} runs: median {statistics.median(speedups):.0f}× real "
        f"time (range {lo:.0f}–{hi:.0f}×), = {statistics.median(ratios):.0f} Python loops"
    )


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    reps = 40 if quick else 200
    setup = "15 km at 1 m (15 001 points), 15 MRSP targets + EoA, 30 gradient steps, 3 brake steps"
    print(f"supervised EBD rebuild from scratch, {setup}: {bench_curves(reps, full=False)}")
    print(
        "all curves (EBD, EBI, SBI, warning, permitted, indication + ceilings) from scratch, "
        f"same line: {bench_curves(reps, full=True)} (goal ≤ 5 ms)"
    )
    print(
        "all curves per cycle (grid, static envelope, its curves and ceilings cached; EoA moved "
        f"over the line), same line: {bench_curves_cycle(reps)} (goal ≤ 5 ms)"
    )
    print(
        "ATP cycle supervised EBD update (static EBD cached, moving EoA laid over it), same line: "
        f"{bench_cycle_update(reps * 5)}"
    )
    print(f"seed 001 two-train 15 km scenario: {bench_scenario(3 if quick else 7)} (goal ≥ 500×)")
    print(
        "baselines (same run): one numpy pass over the 15 001 points = "
        f"{min(_timed(_baseline_pass()) for _ in range(50)) * 1e6:.0f} µs, one Python loop = "
        f"{min(_timed(_python_loop) for _ in range(5)) * 1e3:.2f} ms"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
