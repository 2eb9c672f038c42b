"""`ixl verify` as a whole: the data checks, then the exploration of each station under each
campaign of the bound, printed as it goes and gathered into the JSON document the command prints
(`run_verify`)."""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, TextIO

from ktcs_bench.errors import UsageError
from ktcs_bench.station.loader import default_line_path
from ktcs_bench.station.model import Line
from ktcs_bench.verify.data import check_line
from ktcs_bench.verify.explore import Bound, StationResult, Violation, explore_station
from ktcs_bench.verify.procedure import write_procedure


def _reference(line: Line) -> bool:
    """The line is the shipped reference line (the procedures' quiet lab runs it)."""
    return Path(line.file).resolve() == default_line_path().resolve()


def _search(task: tuple[Line, int, Bound]) -> StationResult:
    line, number, bound = task
    return explore_station(line, number, bound)


def _searches(tasks: list[tuple[Line, int, Bound]], jobs: int) -> Iterator[StationResult]:
    """The searches' results in the tasks' order, run here or in `jobs` worker processes."""
    if jobs <= 1 or len(tasks) <= 1:
        yield from map(_search, tasks)
        return
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        yield from pool.map(_search, tasks)


def describe(step: tuple[str, ...]) -> str:
    return " ".join(step)


def run_verify(
    line: Line,
    *,
    bound_text: str = "",
    stations: list[int] | None = None,
    data_only: bool = False,
    procedures: Path | None = None,
    jobs: int = 1,
    out: TextIO | None = None,
) -> dict[str, Any]:
    """Everything `ixl verify` reports: keys states, transitions, bound, seconds, stations,
    findings, violations. `procedures`: a folder to write each violation into as a procedure for
    `test run` on the reference lab (the reference line only). `jobs`: searches run side by side
    in so many processes (each search is independent: a station under one campaign). `out`: where to print the human
    account as it goes (None: silent)."""
    started = time.monotonic()
    campaigns = Bound.parse_all(bound_text)
    chosen = sorted(line.stations) if not stations else sorted(set(stations))
    for number in chosen:
        if number not in line.stations:
            raise UsageError(f"no station {number} on line {line.name} "
                             f"({', '.join(map(str, sorted(line.stations)))})")  # fmt: skip
    findings = check_line(line)

    def say(text: str) -> None:
        if out is not None:
            print(text, file=out, flush=True)

    say(f"line {line.name}: the data against the geometry, {len(line.stations)} station(s): "
        f"{len(findings) or 'no'} finding(s)")  # fmt: skip
    for f in findings:
        say(f"  FINDING {f}")
    result: dict[str, Any] = {
        "states": 0,
        "transitions": 0,
        "bound": [c.text() for c in campaigns],
        "seconds": 0.0,
        "stations": {},
        "findings": [f.as_dict() for f in findings],
        "violations": [],
    }
    if not data_only:
        say("every reachable state of the interlocking core, station by station, within the "
            "bound (one search per campaign):")  # fmt: skip
        for c in campaigns:
            say(f"  campaign {c.text()}")
    violations: list[Violation] = []
    tasks = [] if data_only else [(line, number, c) for number in chosen for c in campaigns]
    searched = iter(_searches(tasks, jobs))
    for number in [] if data_only else chosen:
        totals = {"states": 0, "transitions": 0, "seconds": 0.0, "complete": True}
        for c in campaigns:
            r = next(searched)
            totals["states"] += r.states
            totals["transitions"] += r.transitions
            totals["seconds"] += r.seconds
            totals["complete"] = bool(totals["complete"]) and r.complete
            violations += r.violations
            for v in r.violations:
                say(f"  VIOLATION station {number} ({c.text()}): {'; '.join(v.what)}")
                say(f"    shortest input sequence ({len(v.steps)} steps):")
                for i, step in enumerate(v.steps, 1):
                    say(f"      {i:3d}. {describe(step)}")
                if procedures is not None and _reference(line):
                    path = write_procedure(line, c, v, procedures, len(violations))
                    say(f"    written as a procedure: {path} (ktcs-bench test run {path})")
                elif procedures is not None:
                    say("    (no procedure written: the procedures' lab runs the reference line)")
        rate = totals["states"] / totals["seconds"] if totals["seconds"] else 0.0
        say(f"  station {number}: {totals['states']} states, {totals['transitions']} transitions, "
            f"{totals['seconds']:.1f} s ({rate:.0f} states/s)"
            f"{'' if totals['complete'] else ', STOPPED SHORT at the state cap'}")  # fmt: skip
        result["states"] += totals["states"]
        result["transitions"] += totals["transitions"]
        result["stations"][str(number)] = {
            **totals, "seconds": round(float(totals["seconds"]), 3),
            "states_per_second": round(rate),
        }  # fmt: skip
    result["violations"] = [v.as_dict() for v in violations]
    result["seconds"] = round(time.monotonic() - started, 3)
    if not data_only:
        say(f"{result['states']} states, {result['transitions']} transitions in "
            f"{result['seconds']:.1f} s: {len(violations) or 'no'} violation(s) of SPEC §6.2 "
            "invariants 1-6 and §6.7")  # fmt: skip
    return result
