"""`ktcs-bench threats`: the seven EN 50159 threats injected through taps into a lab of our
emulators, each reported with the defence that caught it and the application outcome."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ktcs_bench.errors import UsageError

HELP = "inject the EN 50159 threats into a running lab link and report the defences"
DESCRIPTION = """\
Start a small lab (CTC, one station's IXL and ATC, the track circuits) with a pty tap on the Type I
link and a TCP tap on the Type II link, inject repetition, deletion, insertion, resequencing,
corruption, delay and masquerade one after the other, and report for each the defence that caught
it (SEQ, CRC, timeout, IDENT/admission) and what the application did.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("threats", help=HELP, description=DESCRIPTION)
    p.add_argument("--station", type=int, default=18, help="station of the lab (default 18)")
    p.add_argument("--lab", help="lab file for the line data (default: the reference lab)")
    p.add_argument("--threat", action="append", default=[], help="run only these threats")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--markdown", metavar="FILE", help="also write the Markdown table here")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.conformance.threats import THREATS, ThreatLab, markdown, run_threats

    unknown = [t for t in args.threat if t not in THREATS]
    if unknown:
        raise UsageError(f"unknown threat(s) {', '.join(unknown)} (known: {', '.join(THREATS)})")
    with ThreatLab(args.station, args.lab) as lab:
        results = run_threats(lab, args.threat or None)
    table = markdown(results)
    if args.markdown:
        try:
            Path(args.markdown).write_text(table + "\n", encoding="utf-8")
        except OSError as exc:
            raise UsageError(f"cannot write {args.markdown}: {exc.strerror}") from None
    if args.json:
        print(json.dumps([r.as_dict() for r in results], ensure_ascii=False, indent=2))
    else:
        print(table)
        for r in results:
            print(f"\n{r.threat}: " + "; ".join(r.evidence))
    sys.stdout.flush()
    return 0 if all(r.caught and r.safe for r in results) else 1
