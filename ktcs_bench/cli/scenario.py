"""`ktcs-bench scenario run FILE`: a deterministic virtual-time run with assertions and a report.

Thin: argument parsing over `ktcs_bench.scenario`. Exit codes: 0 all assertions pass, 1 one
failed, 2 bad scenario file.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

EPILOG = """\
example:
  ktcs-bench scenario run emulators/scenarios/seed001_follower.yaml --out /tmp/report

writes speed_distance.png and time_distance.png, each with the data it draws as .csv beside
it, events.log and summary.json into --out (default: ./scenario-report/<scenario name>). Exit codes: 0 all assertions pass, 1 an assertion
failed, 2 bad scenario file.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "scenario",
        help="run a scripted scenario in virtual time and check its assertions",
        description="Scenarios: trains under ATP/ATO on a line, run in virtual time.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ssub = p.add_subparsers(dest="scenario_command", metavar="ACTION")
    run_p = ssub.add_parser(
        "run",
        help="run FILE and write its report",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run_p.add_argument("file", metavar="FILE", help="scenario YAML (see emulators/scenarios/)")
    run_p.add_argument("--out", metavar="DIR", help="report folder")
    run_p.add_argument("--json", action="store_true", help="print the JSON summary on stdout")
    run_p.set_defaults(handler=_run)
    p.set_defaults(handler=lambda args: (p.print_help(), 2)[1])


class _Progress:
    def __init__(self, name: str) -> None:
        self.name = name
        self.tty = sys.stderr.isatty()
        self.last = -1

    def __call__(self, frac: float) -> None:
        pct = int(frac * 100)
        if self.tty:
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r{self.name} [{bar:<25}] {pct:3d}%")
            if pct >= 100:
                sys.stderr.write("\n")
            sys.stderr.flush()
        elif pct // 25 > self.last // 25 or pct == 100 and self.last != 100:
            sys.stderr.write(f"{self.name}: {pct}%\n")
        self.last = pct


def _run(args: argparse.Namespace) -> int:
    from ktcs_bench.scenario.assertions import check_all
    from ktcs_bench.scenario.model import load_scenario
    from ktcs_bench.scenario.report import summary, write_report
    from ktcs_bench.scenario.runner import run

    scn = load_scenario(args.file)
    t0 = time.perf_counter()
    result = run(scn, _Progress(scn.name))
    wall = time.perf_counter() - t0
    outcomes = check_all(result)
    out = Path(args.out) if args.out else Path("scenario-report") / scn.name
    paths = write_report(result, outcomes, out, wall)
    if args.json:
        print(json.dumps(summary(result, outcomes, wall), ensure_ascii=False))
    else:
        print(
            f"{scn.name}: {result.end_time:.1f} s virtual in {wall:.2f} s "
            f"({result.end_time / wall:.0f}× real time)"
        )
        for o in outcomes:
            print(f"  {'PASS' if o.passed else 'FAIL'}  {o.assertion.place}: {o.detail}")
        print(f"report: {', '.join(str(p) for p in paths.values())}")
    return 0 if all(o.passed for o in outcomes) else 1
