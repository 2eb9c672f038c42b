"""Issue 15 §4: the whole reference lab in one process on the virtual clock (`lab simulate`), one
hour of virtual time -- its three stations, CTC, track circuits and two trains running the
timetable under ARS, every Type I link paced at 9600 bit/s on its virtual wire through its tap,
Type II through its tap on memory streams, events and pcapng captures written. Goal: >= 200x real
time.

Prints the wall time, the CPU time of this process (the machine is a shared 2-core VM: the CPU
figure is what the run costs, the wall figure what it took beside the other work), the speed-up
against both, what the lab did (events, frames captured, train arrivals) and where the time went
(the run's most expensive functions, from a profile of a tenth of the run).

    .venv/bin/python benchmarks/virtual_lab.py [--hours 1] [--lab reference] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import tempfile
import time
from pathlib import Path
from typing import Any

from ktcs_bench.capture import read_capture
from ktcs_bench.lab.inprocess import InProcessLab

GOAL = 200.0


def simulate(
    lab: str, seconds: float, out: Path, seed: int = 1, invariants: bool = True
) -> dict[str, Any]:
    """Run `lab` for `seconds` of virtual time, the lab invariants checked throughout (as `lab
    simulate` does; `--no-invariants`: without); wall and CPU time of the run (start-up
    included: the devices' construction and their links' first synchronisation)."""
    sim = InProcessLab(lab, seed=seed, out=out, invariants=invariants)
    wall, cpu = time.monotonic(), time.process_time()
    sim.run(lambda lab: lab.sleep(seconds))
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    frames = sum(len(read_capture(str(p)).records) for p in (out / "captures").iterdir())
    events = len((out / "events.jsonl").read_text(encoding="utf-8").splitlines())
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    return {"virtual_s": seconds, "wall_s": wall, "cpu_s": cpu, "frames": frames,
            "events": events, "summary": summary}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=1.0, help="virtual hours (default 1)")
    ap.add_argument("--lab", default="reference")
    ap.add_argument("--profile", action="store_true", help="profile a tenth of the run first")
    ap.add_argument("--no-invariants", dest="invariants", action="store_false",
                    help="without the lab invariants checked throughout")  # fmt: skip
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    seconds = args.hours * 3600
    with tempfile.TemporaryDirectory() as tmp:
        r = simulate(args.lab, seconds, Path(tmp) / "run", invariants=args.invariants)
        print(f"{args.lab}: {seconds:.0f} s of virtual time in {r['wall_s']:.1f} s wall, "
              f"{r['cpu_s']:.1f} s CPU: {seconds / r['wall_s']:.0f}x real time by the wall, "
              f"{seconds / r['cpu_s']:.0f}x by CPU (goal >= {GOAL:.0f}x)")  # fmt: skip
        print(f"  {r['frames']} frames captured on {len(InProcessLab(args.lab).links)} links, "
              f"{r['events']} events, {len(r['summary'].get('violations', []))} violations of "
              f"the lab invariants" + ("" if args.invariants else " (not checked)"))  # fmt: skip
        for name, train in r["summary"]["trains"].items():
            arrivals = train.get("arrivals")
            stops = ", ".join(str(a.get("station", a)) if isinstance(a, dict) else str(a)
                              for a in arrivals or [])  # fmt: skip
            print(f"  {name}: arrived at [{stops}], {train.get('state')} at "
                  f"{train.get('head')} m")  # fmt: skip
        if args.profile:
            profiler = cProfile.Profile()
            profiler.enable()
            simulate(args.lab, seconds / 10, Path(tmp) / "profiled", invariants=args.invariants)
            profiler.disable()
            text = io.StringIO()
            pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(15)
            lines = text.getvalue().splitlines()
            head = next((i for i, line in enumerate(lines) if "ncalls" in line), 0)
            print("where the time goes (a tenth of the run, profiled; by own time):")
            print("\n".join(lines[head : head + 16]))


if __name__ == "__main__":
    main()
