"""What one procedure run exercised (SPEC §12: operation coverage), read off its timeline and its
steps -- the procedure's side of `evidence.coverage`, which knows nothing of procedures."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ktcs_bench import messages as msg
from ktcs_bench.evidence.coverage import CATEGORIES, OperationCoverage
from ktcs_bench.procedure.steps import CtcStep, FaultStep

if TYPE_CHECKING:
    from ktcs_bench.procedure.runner import ProcedureResult


def procedure_coverage(result: ProcedureResult) -> OperationCoverage:
    """A procedure run's coverage (a `procedure.runner.ProcedureResult`), from its timeline --
    the CTC's routes and points, the interlockings' signals, the ATC codes -- and its steps: the
    faults it set, the routes the CTC cancelled (a route gone after a cancel was cancelled; one
    gone without, released by its train or timed out)."""
    proc = result.procedure
    cov = OperationCoverage(proc.setup.lab, proc.names.line)
    cov.observed.update(CATEGORIES)
    cancels: list[tuple[float, str, str]] = []
    for step, sr in zip(proc.steps, result.steps, strict=False):
        if sr.verdict != "pass":
            continue
        if isinstance(step, FaultStep) and step.target != "clear":
            cov.fault(step.text)
        elif isinstance(step, CtcStep) and isinstance(step.command, msg.Route):
            c = step.command
            if c.action == "cancel" and step.refused is None and c.station is not None:
                station = proc.names.line.station(int(c.station))
                for route in station.routes:
                    if route.entry == c.entry and route.exit == c.exit:
                        cancels.append((sr.start, str(c.station), route.name))
    set_at: dict[tuple[str, str], float] = {}
    for t, what, value in result.timeline:
        m = OperationCoverage._ROUTES.match(what)
        gone: tuple[tuple[str, str], ...] = ()
        if m:
            gone = tuple((st, r) for when, st, r in cancels
                         if st == m[1] and when >= set_at.get((st, r), -1.0) and when <= t)  # fmt: skip
            for r in set(value.split()) - {"-"}:
                set_at.setdefault((m[1], r), t)
        cov.sample(what, value, gone)
        if m:
            for key in [k for k in set_at if k[0] == m[1] and k[1] not in value.split()]:
                del set_at[key]
    return cov
