"""`ktcs-bench line generate --stations N --out DIR`: a synthetic N-station line for scale runs.

Thin front over `ktcs_bench.lab.generate` (the files' text: `ktcs_bench.station.generate`): writes the line, its stations, a lab file, a
timetable and the code charts, then loads the lab it wrote (the same checks `lab up` makes).
Exit 0 written, 2 a bad N or an output folder that is not empty (without --force).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ktcs_bench import kinds
from ktcs_bench.cli._common import positive
from ktcs_bench.errors import UsageError
from ktcs_bench.lab.generate import write_line
from ktcs_bench.station.generate import (
    CHARTS_DIR,
    LAB_FILE,
    LINE_FILE,
    MAX_STATIONS,
    TIMETABLE_FILE,
    run_through_s,
)

EPILOG = f"""\
examples:
  ktcs-bench line generate --stations 10 --out /tmp/line10
  ktcs-bench lab up /tmp/line10/lab.yaml            # the generated line live
  ktcs-bench lab simulate /tmp/line10/lab.yaml --for 3600 --out /tmp/run10
                                                    # ... in one process, in virtual time
  ktcs-bench chart check --charts /tmp/line10/code_charts --line /tmp/line10/line.yaml

writes DIR/{LINE_FILE}, DIR/stations/stNN.yaml, DIR/{LAB_FILE}, DIR/{TIMETABLE_FILE} and
DIR/{CHARTS_DIR}/. The lab runs the timetable's two trains (a train device each; the CTC's
automatic route setting sets their routes). Stations are numbered 12, 14, ... (1 to
{MAX_STATIONS} stations) and follow the reference stations 18, 20, 22 in turn. The same N always
gives the same files, byte for byte.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "line",
        help="generate a synthetic line (stations, line, lab, timetable, code charts)",
        description="Generate a synthetic line of N stations on the reference stations' "
        "patterns, with its lab file, a timetable and its code charts.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(dest="line_command", metavar="ACTION", required=True)
    gen = actions.add_parser(
        "generate",
        help="write an N-station line into a folder",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    gen.add_argument(
        "--stations", type=positive(int), required=True, metavar="N",
        help=f"number of stations (1..{MAX_STATIONS})",
    )  # fmt: skip
    gen.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    gen.add_argument(
        "--force", action="store_true",
        help="write into a folder that is not empty, replacing a line generated there before",
    )  # fmt: skip
    gen.set_defaults(handler=_generate)


def _generate(args: argparse.Namespace) -> int:
    from ktcs_bench.lab.topology import load_lab

    out: Path = args.out
    try:
        written = write_line(args.stations, out, force=args.force)
    except OSError as exc:
        raise UsageError(f"cannot write {exc.filename or out}: {exc.strerror or exc}") from None
    lab = load_lab(out / LAB_FILE)
    line = lab.load_line()
    charts = [p for p in written if p.parent.name == CHARTS_DIR]
    numbers = sorted(line.stations)
    span = f"{numbers[0]}" if len(numbers) == 1 else f"{numbers[0]}..{numbers[-1]}"
    print(f"wrote {out}:")
    print(f"  {LINE_FILE}: line {line.name}, {len(numbers)} station(s) {span}, "
          f"{(line.end_m - line.start_m) / 1000:g} km")  # fmt: skip
    print(f"  stations/: {len(numbers)} station file(s)")
    trains = [d for d in lab.devices.values() if d.kind == kinds.TRAIN]
    print(f"  {LAB_FILE}: lab {lab.name}, {len(lab.devices)} devices ({len(trains)} trains, "
          f"routes set by ARS), {len(lab.links)} links")  # fmt: skip
    print(f"  {TIMETABLE_FILE}: {len(trains)} trains end to end")
    print(f"  {CHARTS_DIR}/: {len(charts)} code charts")
    print(f"run it: ktcs-bench lab up {out / LAB_FILE}")
    print(f"   or in one process, in virtual time: ktcs-bench lab simulate {out / LAB_FILE} "
          f"--for {run_through_s(args.stations)} --out RUN")  # fmt: skip
    return 0
