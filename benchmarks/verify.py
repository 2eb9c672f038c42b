"""`ixl verify` figures (SPEC §13, issue 25): the reference line's exhaustive verification timed
end to end -- the data checks and every station's search under the default bound -- with the
states explored per station and per second. Goal: <= 60 s on the bench machine. With
`--generated N`, a generated N-station line (`line generate`) as well (goal at 20: <= 10 min).

Run: python benchmarks/verify.py [--generated 20] [--bound 'requests=2;requests=1,trains=1']
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from ktcs_bench.lab.generate import write_line
from ktcs_bench.station import load_line
from ktcs_bench.station.model import Line
from ktcs_bench.verify.report import run_verify

GOAL_REFERENCE_S = 60.0
GOAL_20_STATIONS_S = 600.0


def figures(name: str, line: Line, bound: str, goal_s: float | None, jobs: int) -> bool:
    started = time.monotonic()
    cpu = _cpu()
    result = run_verify(line, bound_text=bound, jobs=jobs)
    wall, cpu = time.monotonic() - started, _cpu() - cpu
    print(f"{name}: {len(line.stations)} stations, {jobs} process(es), {result['states']} states, "
          f"{result['transitions']} transitions, {wall:.1f} s ({cpu:.1f} s CPU), "
          f"{result['states'] / wall:.0f} states/s")  # fmt: skip
    print(f"  bound: {' ; '.join(result['bound'])}")
    print(f"  {'station':>7} {'states':>8} {'transitions':>11} {'seconds':>8} {'states/s':>9}")
    for number, s in result["stations"].items():
        print(f"  {number:>7} {s['states']:>8} {s['transitions']:>11} {s['seconds']:>8.1f} "
              f"{s['states_per_second']:>9}")  # fmt: skip
    print(f"  findings {len(result['findings'])}, violations {len(result['violations'])}")
    ok = not result["findings"] and not result["violations"]
    if goal_s is not None:
        met = wall <= goal_s
        print(f"  goal <= {goal_s:g} s: {'met' if met else 'NOT met'} (wall clock; other "
              "processes on the machine count against it)")  # fmt: skip
    return ok


def _cpu() -> float:
    """CPU seconds of this process and of the worker processes it has waited for."""
    me, children = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return me.ru_utime + me.ru_stime + children.ru_utime + children.ru_stime


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--generated", type=int, metavar="N", help="also a generated N-station line"
    )
    parser.add_argument("--bound", default="", help="campaigns (default: ixl verify's default)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                        help="worker processes (default: 2, as ixl verify)")  # fmt: skip
    args = parser.parse_args()
    ok = figures("reference line", load_line(), args.bound, GOAL_REFERENCE_S, args.jobs)
    if args.generated:
        with tempfile.TemporaryDirectory() as tmp:
            write_line(args.generated, Path(tmp))
            line = load_line(Path(tmp) / "line.yaml")
            goal = GOAL_20_STATIONS_S if args.generated == 20 else None
            name = f"generated line of {args.generated}"
            ok = figures(name, line, args.bound, goal, args.jobs) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
