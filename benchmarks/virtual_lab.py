"""Issue 15 §4 and issue 26 §4: the whole lab in one process on the virtual clock (`lab simulate`).

The reference lab, one hour of virtual time -- its three stations, CTC, track circuits and trains
running the timetable under ARS, every Type I link paced at 9600 bit/s on its virtual wire through
its tap, Type II through its tap on memory streams, events and pcapng captures written. Goal:
>= 400x real time. Then a generated 43-station line (`line generate 43`, its two trains, every
link through its tap), LINE_S of virtual time. Goal: >= 50x.

Prints, for each, the wall time, the CPU time of this process (the machine is a shared 2-core VM:
the CPU figure is what the run costs, the wall figure what it took beside the other work) and the
speed-up against both, with the load average beside it; what the reference lab did (events,
frames captured, train arrivals); with --profile, where the time went (the run's most expensive
functions, from a profile of a tenth of the reference run).

    .venv/bin/python benchmarks/virtual_lab.py [--hours 1] [--lab reference] [--stations 43]
                                               [--line-seconds 600] [--profile]
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
from ktcs_bench.lab.generate import write_line
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.station.generate import LAB_FILE

GOAL = 400.0  # the reference lab with its trains, x real time
LINE_GOAL = 50.0  # a generated line of LINE_STATIONS stations, x real time
LINE_STATIONS = 43
LINE_S = 600.0  # virtual seconds of the generated line


def simulate(
    lab: str | Path, seconds: float, out: Path, seed: int = 1, invariants: bool = True
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


def load() -> str:
    """The machine's load average over the last minute, as printed beside each figure."""
    return f"load average {os.getloadavg()[0]:.1f}"


def ratios(r: dict[str, Any], goal: float | None) -> str:
    """The run's speed-up by the wall and by CPU, against `goal` if it has one, and the load."""
    seconds, cpu = r["virtual_s"], r["cpu_s"]
    verdict = "" if goal is None else (
        f" (goal >= {goal:.0f}x: {'met' if seconds / cpu >= goal else 'NOT met'} by CPU)")  # fmt: skip
    return (f"{seconds:.0f} s of virtual time in {r['wall_s']:.1f} s wall, {cpu:.1f} s CPU: "
            f"{seconds / r['wall_s']:.0f}x real time by the wall, {seconds / cpu:.0f}x by "
            f"CPU{verdict}, {load()}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=1.0, help="virtual hours (default 1)")
    ap.add_argument("--lab", default="reference")
    ap.add_argument("--profile", action="store_true", help="profile a tenth of the run first")
    ap.add_argument("--no-invariants", dest="invariants", action="store_false",
                    help="without the lab invariants checked throughout")  # fmt: skip
    ap.add_argument("--stations", type=int, default=LINE_STATIONS,
                    help=f"stations of the generated line (default {LINE_STATIONS}; 0: none)")  # fmt: skip
    ap.add_argument("--line-seconds", type=float, default=LINE_S,
                    help=f"virtual seconds of the generated line (default {LINE_S:.0f})")  # fmt: skip
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, {load()} at start")
    seconds = args.hours * 3600
    with tempfile.TemporaryDirectory() as tmp:
        r = simulate(args.lab, seconds, Path(tmp) / "run", invariants=args.invariants)
        print(f"{args.lab}: {ratios(r, GOAL)}", flush=True)
        print(f"  {r['frames']} frames captured on {len(InProcessLab(args.lab).links)} links, "
              f"{r['events']} events, {len(r['summary'].get('violations', []))} violations of "
              f"the lab invariants" + ("" if args.invariants else " (not checked)"))  # fmt: skip
        for name, train in r["summary"]["trains"].items():
            arrivals = train.get("arrivals")
            stops = ", ".join(str(a.get("station", a)) if isinstance(a, dict) else str(a)
                              for a in arrivals or [])  # fmt: skip
            print(f"  {name}: arrived at [{stops}], {train.get('state')} at "
                  f"{train.get('head')} m")  # fmt: skip
        if args.stations:
            n = args.stations
            write_line(n, Path(tmp) / "line")
            line = simulate(Path(tmp) / "line" / LAB_FILE, args.line_seconds, Path(tmp) / "line-run",
                            invariants=args.invariants)  # fmt: skip
            goal = LINE_GOAL if n == LINE_STATIONS else None
            print(f"generated {n}-station line: {ratios(line, goal)}")
            print(f"  {line['frames']} frames captured, {line['events']} events, "
                  f"{len(line['summary'].get('violations', []))} violations of the lab invariants"
                  + ("" if args.invariants else " (not checked)"))  # fmt: skip
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
