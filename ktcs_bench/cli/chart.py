"""`ktcs-bench chart generate|check`: code charts from station data, and their consistency check.

Thin front over `ktcs_bench.chart_files` (`files.generate`, `check.check_charts`). `check` exits 1
when a chart disagrees with the station data or the emulators (unknown, duplicate, missing or
misordered codes), 0 when all agree.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ktcs_bench.chart_files.check import check_charts
from ktcs_bench.chart_files.files import generate
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.station.loader import load_line

EPILOG = """\
examples:
  ktcs-bench chart generate                  # rewrite code_charts/ from emulators/lines/reference.yaml
  ktcs-bench chart generate --out /tmp/charts
  ktcs-bench chart check                     # exit 0 when charts, station data and emulators agree
  ktcs-bench chart check --charts /tmp/charts --line my_lab/line.yaml
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = sub.add_parser(
        "chart",
        help="generate and check the code charts",
        description="Generate the code charts (one per station link and direction) from station "
        "data, or check that the charts, the station data and the emulators agree.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="chart_command", metavar="ACTION", required=True)
    gen = actions.add_parser(
        "generate",
        help="write the charts from station data",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    gen.add_argument("--out", type=Path, help="output folder (default: the shipped code_charts/)")
    gen.add_argument("--line", type=Path, help="line file (default: the reference line)")
    gen.set_defaults(handler=_generate)
    chk = actions.add_parser(
        "check",
        help="check charts against station data and emulators",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    chk.add_argument("--charts", type=Path, help="chart folder (default: the shipped code_charts/)")
    chk.add_argument("--line", type=Path, help="line file (default: the reference line)")
    chk.set_defaults(handler=_check)


def _generate(args: argparse.Namespace) -> int:
    line = load_line(args.line)
    out = args.out if args.out is not None else data_dir("code_charts")
    for path in generate(line, out, _source_name(args.line)):
        print(f"wrote {path}")
    return 0


def _check(args: argparse.Namespace) -> int:
    charts = args.charts if args.charts is not None else data_dir("code_charts")
    try:
        line = load_line(args.line)
    except ConfigError as exc:
        print(f"chart check: {exc}", file=sys.stderr)
        return 1
    problems = check_charts(line, charts)
    for problem in problems:
        print(f"chart check: {problem}", file=sys.stderr)
    if problems:
        print(f"chart check: {len(problems)} problem(s)", file=sys.stderr)
        return 1
    print(f"chart check: ok ({charts}: charts, station data and emulators agree)")
    return 0


def _source_name(line: Path | None) -> str:
    return str(line) if line is not None else "emulators/lines/reference.yaml"
