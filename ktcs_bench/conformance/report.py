"""Reports of a suite run: JUnit XML (what a CI system reads), JSON, and a human summary with
colour on a terminal. Pure functions of a `SuiteResult` (threat reports: `threats.py`)."""

from __future__ import annotations

import json
from typing import TypedDict

from ktcs_bench.conformance.model import CaseJson, CaseResult, CaseVerdict
from ktcs_bench.conformance.runner import SuiteResult
from ktcs_bench.junit import JUnitCase, JUnitSuite, requirement_properties
from ktcs_bench.junit import junit_xml as write_junit

_COLOUR = {CaseVerdict.PASS: "\x1b[32m", CaseVerdict.FAIL: "\x1b[31m", CaseVerdict.ERROR: "\x1b[35m",
           CaseVerdict.SKIP: "\x1b[33m", CaseVerdict.NOT_APPLICABLE: "\x1b[33m"}  # fmt: skip
_OUTCOME = {CaseVerdict.PASS: "pass", CaseVerdict.FAIL: "fail", CaseVerdict.ERROR: "error",
            CaseVerdict.SKIP: "skip", CaseVerdict.NOT_APPLICABLE: "skip"}  # fmt: skip
_RESET = "\x1b[0m"
_BOLD = "\x1b[1m"


def _frames_text(result: CaseResult) -> str:
    lines = [f"{r.time:9.4f}  {r.direction:13s}  {r.summary:40s}  {r.hex}"
             for r in result.evidence.records]  # fmt: skip
    return "\n".join(["checks:", *result.evidence.checks, "frames:", *lines])


def junit_xml(suite: SuiteResult) -> bytes:
    """One <testsuite> named after the role; one <testcase> per case, evidence in system-out."""
    props = {"role": suite.role, "target": suite.target, "profile": suite.profile,
             "timings": "auto" if suite.auto else "given",
             **suite.timing.describe(),
             **{f"measured.{k}": v for k, v in suite.measured.describe().items()},
             **({"stopped": suite.stopped} if suite.stopped else {})}  # fmt: skip
    cases = []
    for r in suite.results:
        failed = r.verdict is CaseVerdict.FAIL
        cases.append(
            JUnitCase(
                r.case.name,
                f"conformance.{suite.protocol}.{suite.role}",
                r.duration,
                _OUTCOME[r.verdict],
                r.message,
                f"{r.case.title} ({r.case.rule})\n{r.message}" if failed else r.message,
                _frames_text(r),
                "ConformanceFailure" if failed else "SuiteError",
                requirement_properties(r.case.verifies),
            )  # fmt: skip
        )
    name = f"ktcs-bench conformance {suite.role} {suite.protocol}"
    return write_junit("ktcs-bench conformance", [JUnitSuite(name, cases, suite.duration, props)])


class SuiteJson(TypedDict):
    """A suite run's JSON report: who was tested how, the timings, the verdicts and each case."""

    role: str
    target: str
    protocol: str
    profile: str
    timings: str  # "auto" (measured first) or "given"
    timing: dict[str, float | int | None]
    measured: dict[str, float | int | None]
    stopped: str | None
    duration: float
    summary: dict[str, int]  # verdict -> cases
    cases: list[CaseJson]


def as_json(suite: SuiteResult, evidence: bool = True) -> SuiteJson:
    return {
        "role": suite.role,
        "target": suite.target,
        "protocol": suite.protocol,
        "profile": suite.profile,
        "timings": "auto" if suite.auto else "given",
        "timing": suite.timing.describe(),
        "measured": suite.measured.describe(),
        "stopped": suite.stopped,
        "duration": round(suite.duration, 3),
        "summary": {v.value: suite.count(v) for v in CaseVerdict},
        "cases": [r.as_dict(evidence) for r in suite.results],
    }


def json_text(suite: SuiteResult, evidence: bool = True) -> str:
    return json.dumps(as_json(suite, evidence), ensure_ascii=False, indent=2)


def case_line(result: CaseResult, colour: bool) -> str:
    v = result.verdict
    mark = ("N/A" if v is CaseVerdict.NOT_APPLICABLE else v.value.upper()).ljust(5)
    if colour:
        mark = f"{_COLOUR[v]}{_BOLD}{mark}{_RESET}"
    text = f"{mark} {result.case.name:28s} {result.duration:6.2f} s  {result.case.title}"
    if result.message and v is not CaseVerdict.PASS:
        text += f"\n      -> {result.message}"
    return text


def header(suite: SuiteResult) -> str:
    head = (f"ktcs-bench conformance: role {suite.role}, target {suite.target}, "
            f"profile {suite.profile} ({suite.protocol})")  # fmt: skip
    timing = timing_line(suite)
    if suite.auto:
        timing += "\n  --timings auto: measured first; the cases judge by what was measured"
    return f"{head}\n  {timing}"


def timing_line(suite: SuiteResult) -> str:
    """The timings the cases judge by."""
    t = suite.timing
    if suite.protocol == "type1":
        return (f"ΔR {t.delta_r * 1000:.0f} ms, ACK timeout {t.ack_timeout * 1000:.0f} ms, "
                f"link-test period {t.link_test_period:.3g} s, T_MAX {t.t_max:.3g} s, "
                f"retry count {t.retry_count}, tolerance +{t.tolerance:g} s")  # fmt: skip
    return (f"heartbeat period {t.heartbeat_period:.3g} s, T_MAX {t.t2_t_max:.3g} s, "
            f"retry count {t.retry_count}, tolerance +{t.tolerance:g} s")  # fmt: skip


def measured_line(suite: SuiteResult) -> str:
    """The device's timers as the run measured them (empty when no case timed one)."""
    text = suite.measured.text()
    return f"measured: {text}" if text else ""


def case_block(result: CaseResult, colour: bool, verbose: bool = False) -> str:
    """The case's line, and its checks when it did not pass (all of them with `verbose`)."""
    lines = [case_line(result, colour)]
    if verbose or result.verdict in (CaseVerdict.FAIL, CaseVerdict.ERROR):
        checks = result.evidence.checks if verbose else result.evidence.checks[-6:]
        lines.extend("      " + c for c in checks)
    return "\n".join(lines)


def footer(suite: SuiteResult, colour: bool) -> str:
    counts = ", ".join(f"{suite.count(v)} {v.value}" for v in CaseVerdict if suite.count(v))
    verdict = "FAILED" if suite.failed else "PASSED"
    if colour:
        verdict = f"{_COLOUR[CaseVerdict.FAIL if suite.failed else CaseVerdict.PASS]}{_BOLD}{verdict}{_RESET}"
    lines = [f"{verdict}: {counts} in {suite.duration:.1f} s"]
    if measured_line(suite):
        lines.insert(0, measured_line(suite))
    if suite.stopped:
        lines.append(f"stopped: {suite.stopped}")
    return "\n".join(lines)


def summary(suite: SuiteResult, colour: bool, verbose: bool = False) -> str:
    blocks = [case_block(r, colour, verbose) for r in suite.results]
    return "\n".join([header(suite), "", *blocks, "", footer(suite, colour)])
