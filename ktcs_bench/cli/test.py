"""`ktcs-bench test run PROCEDURES...`: integration test procedures against a lab, with verdicts
and reports (`ktcs_bench.procedure`). Exit codes: 0 every procedure passed, 1 one failed, 2 a bad
procedure file or usage, 3 the lab unreachable, 130 interrupted (the faults set are cleared)."""

from __future__ import annotations

import argparse
import asyncio
import importlib
import logging
import sys
import tempfile
from pathlib import Path
from typing import Any

from ktcs_bench.errors import PeerError, UsageError

EPILOG = """\
examples:
  ktcs-bench test run emulators/procedures/*.yaml                 # in one process, virtual time
  ktcs-bench lab up emulators/procedures/labs/quiet.yaml &     # the procedures' lab, live ...
  ktcs-bench test run --live emulators/procedures/route_set.yaml  # ... and a procedure on it
  ktcs-bench test run --live mylab P.yaml --junit out.xml --report out/ # a running lab `mylab`

A procedure is a YAML file: metadata (id, title, verifies, tags), a setup (lab, trains, modes,
ARS) and steps -- CTC commands in the `ctc` console's words, train actions, faults, waits and
expectations with a time limit. The format: docs/procedures.md.

exit codes: 0 every procedure passed, 1 a procedure failed, 2 a bad procedure file or usage,
3 the lab unreachable, 130 interrupted (every fault the run set is cleared first).
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "test", help="run integration test procedures against a lab, with reports",
        description="Integration test procedures: set up, act, expect, record, report.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    tsub = p.add_subparsers(dest="test_command", metavar="ACTION")
    run_p = tsub.add_parser(
        "run", help="run procedures and give a verdict for each", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    run_p.add_argument("procedures", nargs="*", metavar="PROCEDURE", help="procedure YAML files")
    where = run_p.add_mutually_exclusive_group()
    where.add_argument(
        "--virtual", action="store_true",
        help="the whole lab in this process, on a virtual clock (the default)",
    )  # fmt: skip
    where.add_argument(
        "--live", nargs="?", const="", metavar="LAB",
        help="a running `lab up` (default: the lab the procedures name), in real time",
    )  # fmt: skip
    run_p.add_argument("--junit", metavar="FILE", help="write JUnit XML here")
    run_p.add_argument("--report", metavar="DIR", help="write an HTML page per procedure here")
    run_p.add_argument("--json", action="store_true", help="print the results as JSON")
    run_p.set_defaults(handler=run)
    p.set_defaults(handler=lambda args: (p.print_help(), 2)[1])


def _in_process() -> Any:
    """The class that runs a lab in one process on a virtual clock (`lab.inprocess`)."""
    try:
        module = importlib.import_module("ktcs_bench.lab.inprocess")
    except ImportError:
        raise UsageError(
            "this installation cannot run a lab in one process; run the procedures against "
            "a running lab with --live"
        ) from None
    return module.InProcessLab


def _run_virtual(args: argparse.Namespace, procedures: list[Any]) -> tuple[list[Any], bool]:
    """Each procedure on a fresh lab in this process, on the virtual clock."""
    from ktcs_bench.procedure.report import result_text
    from ktcs_bench.procedure.runner import run_procedure

    lab_class = _in_process()
    from ktcs_bench.timed.vloop import VirtualDeadlock

    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)  # the report has their events
    results: list[Any] = []
    for proc in procedures:
        with tempfile.TemporaryDirectory(prefix="ktcs-procedure-") as tmp:
            lab = lab_class(proc.setup.lab, clock="virtual", out=Path(tmp))
            try:
                result = lab.run(lambda access, p=proc: run_procedure(p, access, "virtual"))
            except KeyboardInterrupt:  # the lab, and every fault in it, ends with this process
                return results, True
            except VirtualDeadlock as exc:
                raise PeerError(f"{proc.id}: the lab stalled: {exc}") from None
        results.append(result)
        if not args.json:
            print(result_text(result, args.colour), flush=True)
    return results, False


async def _run_live(args: argparse.Namespace, procedures: list[Any]) -> tuple[list[Any], bool]:
    """Every procedure, in order, on the running lab `--live` names (else the one they name)."""
    from ktcs_bench.lab.access_live import LiveLabAccess
    from ktcs_bench.procedure.report import result_text
    from ktcs_bench.procedure.runner import run_procedure

    names = {args.live} if args.live else {p.setup.lab.name for p in procedures}
    if len(names) > 1:
        raise UsageError(f"the procedures name several labs ({', '.join(sorted(names))}): "
                         "give --live LAB")  # fmt: skip
    name = names.pop()
    access = LiveLabAccess.attach(name)
    results: list[Any] = []
    try:
        for proc in procedures:
            result = await run_procedure(proc, access, f"live {name}")
            results.append(result)
            if not args.json:
                print(result_text(result, args.colour), flush=True)
            if result.interrupted:
                return results, True
            if result.lab_gone:
                break
    finally:
        await access.close()
    return results, False


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.procedure.model import load_procedure
    from ktcs_bench.procedure.report import json_text, junit, write_reports

    if args.live and args.live.endswith((".yaml", ".yml")):  # `--live P.yaml`: no lab named
        args.procedures, args.live = [args.live, *args.procedures], ""
    if not args.procedures:
        raise UsageError("test run: give one procedure file or more")
    procedures = [load_procedure(path) for path in args.procedures]  # every file checked first
    ids = [p.id for p in procedures]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise UsageError(f"procedure id given twice: {', '.join(twice)}")
    if args.junit:
        _writable(Path(args.junit).parent, "--junit")
    if args.live is None:
        results, interrupted = _run_virtual(args, procedures)
    else:
        results, interrupted = asyncio.run(_run_live(args, procedures))
    if args.junit:
        Path(args.junit).write_bytes(junit(results))
    if args.report:
        paths = write_reports(results, Path(args.report))
        if not args.json:
            print(f"report: {paths[0]}")
    if args.json:
        print(json_text(results))
    elif not interrupted:
        passed = sum(1 for r in results if r.verdict == "pass")
        print(f"{passed} of {len(results)} procedures passed", file=sys.stderr)
    if interrupted:
        return 130
    gone = next((r.lab_gone for r in results if r.lab_gone), "")
    if gone:
        raise PeerError(gone)
    return 0 if all(r.verdict == "pass" for r in results) else 1


def _writable(folder: Path, what: str) -> None:
    if not folder.is_dir():
        raise UsageError(f"{what}: no folder {folder}")
