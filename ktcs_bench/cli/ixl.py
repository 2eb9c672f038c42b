"""`ktcs-bench ixl table|verify [LINE]`: the interlocking's control tables, and its exhaustive
verification (SPEC §13) -- the data against the geometry, then every reachable state of the real
interlocking core within a stated bound.

Exit codes of `verify`: 0 nothing found, 1 a data finding or an invariant violation, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from ktcs_bench import kinds
from ktcs_bench.cli._common import positive
from ktcs_bench.errors import UsageError
from ktcs_bench.station.model import Line

EPILOG = """\
examples:
  ktcs-bench ixl table --out /tmp/tables            # the reference line's control tables
  ktcs-bench ixl table /tmp/line10/line.yaml --out /tmp/t10
  ktcs-bench ixl verify                             # data checks, then every reachable state
  ktcs-bench ixl verify --json --bound 'requests=2,trains=1'
  ktcs-bench ixl verify --data-only /tmp/line10/line.yaml

LINE is a line file (default: the shipped reference line, emulators/lines/reference.yaml).
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        kinds.IXL,
        help="the interlocking's control tables and its exhaustive verification",
        description="Control tables derived from the station data, and the verification of the "
        "station data against the point geometry and of every reachable state of the "
        "interlocking core (SPEC §13).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(dest="ixl_command", metavar="ACTION", required=True)
    table = actions.add_parser(
        "table", help="write every station's control table (CSV per station, index.html)",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    table.add_argument("line", nargs="?", type=Path, metavar="LINE", help="line file")
    table.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    table.set_defaults(handler=_table)
    verify = actions.add_parser(
        "verify", help="check the data against the geometry, then every reachable state",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    verify.add_argument("line", nargs="?", type=Path, metavar="LINE", help="line file")
    verify.add_argument("--json", action="store_true", help="one JSON document on stdout")
    verify.add_argument(
        "--bound", default="", metavar="K=V,...",
        help="the exploration's bound: campaigns separated by ';', each key=value,... of depth, "
        "requests, points, modes, trains, faults, env, states (default: the campaigns the "
        "reference line verifies in within a minute, printed)",
    )  # fmt: skip
    verify.add_argument("--station", type=int, action="append", metavar="N",
                        help="explore only this station (repeatable)")  # fmt: skip
    verify.add_argument("--data-only", action="store_true", help="the data checks alone")
    verify.add_argument(
        "--jobs", type=positive(int), default=min(2, os.cpu_count() or 1), metavar="N",
        help="searches side by side in N processes (default: 2, or 1 on one core)",
    )  # fmt: skip
    verify.add_argument("--procedures", type=Path, metavar="DIR",
                        help="write each violation as a procedure for `test run` (reference "
                        "line)")  # fmt: skip
    verify.set_defaults(handler=_verify)


def _load(path: Path | None) -> Line:
    from ktcs_bench.station import load_line

    if path is not None and not path.is_file():
        raise UsageError(f"no line file {path}")
    return load_line(path)


def _table(args: argparse.Namespace) -> int:
    from ktcs_bench.verify.table import write_tables

    line = _load(args.line)
    try:
        written = write_tables(line, args.out)
    except OSError as exc:
        raise UsageError(
            f"cannot write {exc.filename or args.out}: {exc.strerror or exc}"
        ) from None
    for path in written:
        print(f"wrote {path}")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from ktcs_bench.verify.report import run_verify

    line = _load(args.line)
    result = run_verify(
        line, bound_text=args.bound, stations=args.station, data_only=args.data_only,
        procedures=args.procedures, jobs=args.jobs, out=None if args.json else sys.stdout,
    )  # fmt: skip
    if args.json:
        print(json.dumps(result, indent=1))
    return 1 if result["findings"] or result["violations"] else 0
