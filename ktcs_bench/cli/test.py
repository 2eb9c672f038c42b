"""`ktcs-bench test run PROCEDURES...`: integration test procedures against a lab, with verdicts
and reports (`ktcs_bench.procedure`). Exit codes: 0 every procedure passed, 1 one failed, 2 a bad
procedure file, report path or usage, 3 the lab unreachable, 130 interrupted by SIGINT, 143 by
SIGTERM (the faults set are cleared, the reports written)."""

from __future__ import annotations

import argparse
import asyncio
import importlib
import logging
import os
import signal
import sys
import tempfile
from collections import Counter
from collections.abc import Coroutine
from pathlib import Path
from typing import Any

from ktcs_bench.cli._common import output_folder, probe_writable
from ktcs_bench.errors import PeerError, UsageError

EPILOG = """\
examples:
  ktcs-bench test run emulators/procedures/*.yaml                 # in one process, virtual time
  ktcs-bench test run emulators/procedures --report out/          # a folder: every *.yaml in it
  ktcs-bench lab up emulators/procedures/labs/quiet.yaml &     # the procedures' lab, live ...
  ktcs-bench test run --live emulators/procedures/route_set.yaml  # ... and a procedure on it
  ktcs-bench test run --live mylab P.yaml --junit out.xml --report out/ # a running lab `mylab`

A procedure is a YAML file: metadata (id, title, verifies, tags), a setup (lab, trains, modes,
ARS) and steps -- CTC commands in the `ctc` console's words, train actions, faults, waits and
expectations with a time limit. The format: docs/procedures.md.

exit codes: 0 every procedure passed, 1 a procedure failed, 2 a bad procedure file, report path
or usage, 3 the lab unreachable, 130 interrupted by SIGINT (Ctrl-C), 143 by SIGTERM (every fault the
run set is cleared first; the reports are written, the procedure it was in an error, the rest skipped).
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
    run_p.add_argument("procedures", nargs="*", metavar="PROCEDURE",
                       help="procedure YAML files, or folders of them")  # fmt: skip
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
    run_p.add_argument("--report", metavar="DIR",
                       help="write an HTML page per procedure, an index and the JSON here")  # fmt: skip
    run_p.add_argument("--json", action="store_true", help="print the results as JSON")
    run_p.add_argument(
        "--keep-going", action="store_true",
        help="run the steps after a failed expectation too (reported after it): what the lab "
             "did after an unsafe state is recorded",
    )  # fmt: skip
    run_p.add_argument(
        "--catalogue", metavar="FILE",
        help="the requirements catalogue `verifies:` ids are checked against "
             "(default: the shipped emulators/requirements/ktcs.yaml)",
    )  # fmt: skip
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


class _Stop:
    """SIGINT and SIGTERM during a run. The first cancels the procedure running -- it clears its
    faults and is recorded as interrupted (between two, the next is, before its setup) -- and no
    procedure starts after it; the later ones are ignored while the run winds up and writes its
    reports. A handler of the process (not of the loop: the virtual loop never waits on its
    wake-up pipe), installed for the whole run."""

    def __init__(self) -> None:
        self.signum = 0
        self._task: asyncio.Task[Any] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> _Stop:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)

    def _handle(self, signum: int, _frame: object) -> None:
        if self.signum:
            return
        self.signum = signum
        task, loop = self._task, self._loop
        if task is not None and loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(task.cancel)

    async def run(self, procedure: Coroutine[Any, Any, Any]) -> Any:
        """The procedure's run as a task the first signal cancels; None if a signal came before
        it began."""
        if self.signum:
            procedure.close()
            return None
        self._loop = asyncio.get_running_loop()
        task = self._task = self._loop.create_task(procedure)
        try:
            return await task
        except asyncio.CancelledError:
            me = asyncio.current_task()
            if task.cancelled() and self.signum and (me is None or not me.cancelling()):
                return None  # cancelled before its first step: it never began
            raise
        finally:
            self._task = None


def _run_virtual(args: argparse.Namespace, procedures: list[Any], stop: _Stop) -> list[Any]:
    """Each procedure on a fresh lab in this process, on the virtual clock, until a signal."""
    from ktcs_bench.procedure.report import result_text
    from ktcs_bench.procedure.runner import run_procedure, unfinished

    lab_class = _in_process()
    from ktcs_bench.timed.vloop import VirtualDeadlock

    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)  # the report has their events
    results: list[Any] = []
    for proc in procedures:
        result = None
        if not stop.signum:
            with tempfile.TemporaryDirectory(prefix="ktcs-procedure-") as tmp:
                lab = lab_class(proc.setup.lab, clock="virtual", out=Path(tmp))
                try:
                    result = lab.run(lambda access, p=proc: stop.run(run_procedure(
                        p, access, "virtual", keep_going=args.keep_going)))  # fmt: skip
                except VirtualDeadlock as exc:
                    raise PeerError(f"{proc.id}: the lab stalled: {exc}") from None
        if result is None:  # the next one to run is the one interrupted
            result = unfinished(proc, "virtual", interrupted="before its setup")
        results.append(result)
        if not args.json:
            print(result_text(result, args.colour), flush=True)
        if result.interrupted:
            break
    return results


async def _run_live(args: argparse.Namespace, procedures: list[Any], stop: _Stop) -> list[Any]:
    """Every procedure, in order, on the running lab `--live` names (else the one they name),
    until a signal."""
    from ktcs_bench.lab.access_live import LiveLabAccess
    from ktcs_bench.procedure.report import result_text
    from ktcs_bench.procedure.runner import run_procedure, unfinished

    name = _live_lab(args, procedures)
    access = LiveLabAccess.attach(name)
    results: list[Any] = []
    try:
        for proc in procedures:
            result = await stop.run(run_procedure(proc, access, f"live {name}",
                                                  keep_going=args.keep_going))  # fmt: skip
            if result is None:  # the next one to run is the one interrupted
                result = unfinished(proc, f"live {name}", interrupted="before its setup")
            results.append(result)
            if not args.json:
                print(result_text(result, args.colour), flush=True)
            if result.lab_gone or result.interrupted:
                break
    finally:
        await access.close()
    return results


def _live_lab(args: argparse.Namespace, procedures: list[Any]) -> str:
    names = {str(args.live)} if args.live else {str(p.setup.lab.name) for p in procedures}
    if len(names) > 1:
        raise UsageError(f"the procedures name several labs ({', '.join(sorted(names))}): "
                         "give --live LAB")  # fmt: skip
    return names.pop()


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.evidence.catalogue import load_catalogue
    from ktcs_bench.procedure.model import load_procedure
    from ktcs_bench.procedure.report import json_text, junit, write_coverage, write_reports
    from ktcs_bench.procedure.runner import unfinished

    if args.live and _names_files(args.live):  # `--live P.yaml` (or a folder): no lab named
        args.procedures, args.live = [args.live, *args.procedures], ""
    if not args.procedures:
        raise UsageError("test run: give one procedure file or more")
    files = _procedure_files(args.procedures)
    junit_path = _output_file(args.junit, "--junit") if args.junit else None
    report_dir = output_folder(args.report, "--report") if args.report else None
    catalogue = load_catalogue(args.catalogue) if args.catalogue else None
    procedures = [load_procedure(path, catalogue) for path in files]  # every file checked first
    ids = [p.id for p in procedures]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise UsageError(f"procedure id given twice: {', '.join(twice)}")
    if args.live is not None:
        mode = f"live {_live_lab(args, procedures)}"
    else:
        _in_process()  # this installation can run a lab in one process, before anything runs
        mode = "virtual"
    with _Stop() as stop:  # from here on a signal ends the run with its reports written
        if args.live is None:
            results = _run_virtual(args, procedures, stop)
        else:
            results = asyncio.run(_run_live(args, procedures, stop))
        # interrupted: a procedure was (a signal after the last one finished is too late)
        interrupted = any(r.interrupted for r in results)
        why = "the run was interrupted" if interrupted else "the lab went away"
        results += [unfinished(p, mode, not_run=why) for p in procedures[len(results) :]]
        if junit_path is not None:  # the run's operation coverage beside it, named in it
            beside = junit_path.with_name(f"{junit_path.stem}.coverage.json")
            write_coverage(results, beside)
            junit_path.write_bytes(junit(results, beside.name))
        if report_dir is not None:
            paths = write_reports(results, report_dir)
            if not args.json:
                print(f"report: {paths[0]}")
        if args.json:
            print(json_text(results))
        else:
            counts = Counter(r.verdict for r in results)
            print(f"{counts['pass']} of {len(results)} procedures passed"
                  + "".join(f", {counts[v]} {w}" for v, w in (("fail", "failed"),
                            ("error", "in error"), ("skipped", "not run")) if counts[v])
                  + (" (interrupted)" if interrupted else ""), file=sys.stderr)  # fmt: skip
    if interrupted:
        return 128 + stop.signum  # 130 Ctrl-C, 143 SIGTERM, as the shell reports a signal
    gone = next((r.lab_gone for r in results if r.lab_gone), "")
    if gone:
        raise PeerError(gone)
    return 0 if all(r.verdict == "pass" for r in results) else 1


PROCEDURE_SUFFIXES = (".yaml", ".yml")


def _names_files(word: str) -> bool:
    """Whether `--live WORD` names procedure files rather than a lab: a YAML file, or a folder
    given as a path."""
    return word.endswith(PROCEDURE_SUFFIXES) or (os.sep in word and Path(word).is_dir())


def _procedure_files(words: list[str]) -> list[Path]:
    """The files the arguments name: a folder stands for every procedure file in it (*.yaml,
    *.yml; not its sub-folders), sorted by name."""
    files: list[Path] = []
    for word in words:
        path = Path(word)
        if not path.is_dir():
            files.append(path)
            continue
        found = sorted(p for p in path.iterdir() if p.suffix in PROCEDURE_SUFFIXES and p.is_file())
        if not found:
            raise UsageError(f"test run: no procedure file (*.yaml, *.yml) in the folder {word}")
        files += found
    return files


def _output_file(word: str, option: str) -> Path:
    """A file a report is written to, checked before anything runs (its folder there and
    writable, itself no folder); a UsageError naming it and what is wrong."""
    path = Path(word)
    if path.is_dir():
        raise UsageError(f"{option} {word}: is a folder; give a file name")
    folder = path.parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "is not there"
        raise UsageError(f"{option} {word}: {folder} {what}")
    try:
        if path.exists():
            with path.open("ab"):
                pass
        else:
            probe_writable(folder)
    except OSError as exc:
        raise UsageError(f"{option} {word}: cannot write there: {exc.strerror or exc}") from None
    return path
