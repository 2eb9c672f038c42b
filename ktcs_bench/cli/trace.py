"""`ktcs-bench trace RESULTS... --out DIR`: the traceability matrix (`evidence.trace`) from the
requirements catalogue and the results the bench wrote. Exit codes: 0 no requirement has a
failing check, 1 one has, 2 a bad catalogue, results file or usage."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ktcs_bench.cli._common import output_folder

EPILOG = """\
examples:
  ktcs-bench test run emulators/procedures --junit run/junit.xml --report run/report
  ktcs-bench trace run/ --out trace/                  # every JUnit and JSON under run/
  ktcs-bench conformance --role atc --target /dev/ttyUSB0 --junit atc.xml
  pytest tests --junitxml=pytest.xml                  # @pytest.mark.requirement ids as properties
  ktcs-bench trace run/junit.xml atc.xml pytest.xml --out trace/ --json

Writes DIR/trace.json, DIR/trace.csv and DIR/index.html: each requirement of the catalogue with
its status (passed, failed, unchecked), the checks that name it (kind, name, verdict, evidence:
report page, captures) -- failing and unchecked first -- the counts, and the operation coverage
the runs left beside their results (coverage.json): routes never set, points never reversed,
aspects never shown, codes never sent, faults never injected, per station.

exit codes: 0 no requirement has a failing check, 1 one has, 2 a bad catalogue, results file or
usage.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "trace", help="the traceability matrix: requirements, checks, verdicts, evidence",
        description="Requirement -> checks -> verdicts -> evidence, from the results the bench "
                    "wrote, with the operations no run exercised.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    p.add_argument("results", nargs="+", metavar="RESULTS",
                   help="JUnit XML and JSON files the bench (or pytest) wrote, or folders of them")  # fmt: skip
    p.add_argument("--catalogue", metavar="FILE",
                   help="the requirements catalogue (default: emulators/requirements/ktcs.yaml)")  # fmt: skip
    p.add_argument("--out", metavar="DIR", required=True,
                   help="write trace.json, trace.csv and index.html here")  # fmt: skip
    p.add_argument("--json", action="store_true", help="also print the matrix as JSON")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.evidence.catalogue import load_catalogue
    from ktcs_bench.evidence.trace import failing, read_results, summary_lines, trace, write_trace

    catalogue = load_catalogue(args.catalogue)
    out = output_folder(args.out, "--out")
    doc = trace(catalogue, read_results(args.results))
    paths = write_trace(doc, Path(out))
    if args.json:
        print(json.dumps(doc, ensure_ascii=False, indent=1))
    else:
        print("\n".join(summary_lines(doc)))
        print(f"trace: {paths[2]}", file=sys.stderr)
    return 1 if failing(doc) else 0
