"""The conformance suite (SPEC §7, §10); the EN 50159 threat campaign is `ktcs_bench.threats`.

Owns: named cases built from raw frames (`type1_cases`, `type2_cases`), the suite's own wire ends
(`wire`), the timings it judges by (`timing`), the runner, the reports (JUnit XML, JSON, a human
summary). Must not use the bench's link code (`type1/`,
`type2/` sessions) to judge a device -- only the codec.
"""

from ktcs_bench.conformance.model import Case, CaseResult, CaseVerdict
from ktcs_bench.conformance.runner import CASES, SuiteResult, run_suite
from ktcs_bench.conformance.timing import SuiteTiming

__all__ = ["CASES", "Case", "CaseResult", "SuiteResult", "SuiteTiming", "CaseVerdict", "run_suite"]
