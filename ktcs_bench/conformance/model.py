"""Cases, verdicts and what a case is given: the suite's vocabulary, no I/O of its own.

A case is a named function of a `CaseContext`; it passes by returning, fails by `ctx.check`
raising `CaseFailed`, is skipped with `NotApplicable`, and any other exception is an error (the
suite, the line or the peer broke, not the rule) -- `Inconclusive` among them: the suite itself
broke the case's premise (it sent while timing the device's silence). Its `Evidence` is kept
whatever the verdict.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NotRequired, TypedDict

from ktcs_bench import kinds
from ktcs_bench.conformance.timing import MeasuredTiming, SuiteTiming
from ktcs_bench.conformance.wire import Evidence, Type1Wire, Type2Wire


class CaseVerdict(enum.Enum):
    PASS = "pass"
    FAIL = "fail"
    ERROR = "error"
    SKIP = "skip"
    NOT_APPLICABLE = "not applicable"  # the device's statement (ICS) says it has no such part


class CaseFailed(Exception):
    """The device broke the rule the case checks."""


class NotApplicable(Exception):
    """The case does not apply to this role or target."""


@dataclass
class CaseContext:
    role: str
    timing: SuiteTiming
    evidence: Evidence
    station: int | None = None
    codes: int | None = None  # codes in the device's transmit chart, when known
    type1: Type1Wire | None = None
    open_type2: Callable[[], Type2Wire] | None = None
    opened: list[Type2Wire] = field(default_factory=list)
    measured: MeasuredTiming = field(default_factory=MeasuredTiming)

    @property
    def wire(self) -> Type1Wire:
        assert self.type1 is not None
        return self.type1

    def connect(self) -> Type2Wire:
        """A fresh Type II connection for this case (closed when the case ends)."""
        assert self.open_type2 is not None
        w = self.open_type2()
        w.begin(self.evidence)
        self.opened.append(w)
        return w

    def check(self, ok: bool, what: str) -> None:
        """Record one check; a false one fails the case."""
        self.evidence.note(("ok   " if ok else "FAIL ") + what)
        if not ok:
            raise CaseFailed(what)

    def note(self, text: str) -> None:
        self.evidence.note("     " + text)

    def check_period(self, name: str, times: list[float], period: float, limit: float,
                     timer: str) -> None:  # fmt: skip
        """The idle device sends `name` every `period` s (its `timer`): at least two seen in
        `limit` s, and every interval within the timing's bounds."""
        self.check(len(times) >= 2, f"the idle device sends {name} every {period:.3g} s "
                   f"({len(times)} seen in {limit:.1f} s)")  # fmt: skip
        for a, b in zip(times, times[1:], strict=False):
            self.check(self.timing.within(b - a, period),
                       f"{name} interval {(b - a) * 1000:.0f} ms: the {timer} "
                       f"{period * 1000:.0f} ms")  # fmt: skip


CaseFunction = Callable[[CaseContext], None]


@dataclass(frozen=True)
class Case:
    name: str
    protocol: str  # "type1" | "type2"
    title: str
    rule: str  # the SPEC section and rule it checks
    run: CaseFunction
    roles: tuple[str, ...] = kinds.CONFORMANCE_KINDS
    verifies: tuple[str, ...] = ()  # requirement ids of the catalogue (`evidence.catalogue`)


class CaseJson(TypedDict):
    """A case's result in the suite's JSON report; its frames (`EvidenceRecord.as_dict`) only
    when the evidence is asked for."""

    name: str
    title: str
    rule: str
    verifies: list[str]
    verdict: str
    message: str
    duration: float
    checks: list[str]
    frames: NotRequired[list[dict[str, object]]]


@dataclass
class CaseResult:
    case: Case
    verdict: CaseVerdict
    message: str
    duration: float
    evidence: Evidence
    heard: int = 0  # bytes received from the device during the case

    def as_dict(self, evidence: bool = True) -> CaseJson:
        out: CaseJson = {
            "name": self.case.name,
            "title": self.case.title,
            "rule": self.case.rule,
            "verifies": list(self.case.verifies),
            "verdict": self.verdict.value,
            "message": self.message,
            "duration": round(self.duration, 4),
            "checks": list(self.evidence.checks),
        }
        if evidence:
            out["frames"] = [r.as_dict() for r in self.evidence.records]
        return out
