"""Fault variants: emulators that break exactly one protocol rule on purpose, so the conformance
suite can show it catches each (`ktcs-bench emulator KIND --fault VARIANT`).

`FAULTS` names every variant and the rule it breaks; `type1_link()` builds the Type I link a
device's code port uses, with the variant's behaviour when one is selected.
"""

from __future__ import annotations

from collections.abc import Iterable

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError
from ktcs_bench.type1 import LinkConfig, StateProvider, Type1Link

FAULTS: dict[str, str] = {}


def check(names: Iterable[str]) -> frozenset[str]:
    chosen = frozenset(names)
    unknown = sorted(chosen - FAULTS.keys())
    if unknown:
        known = ", ".join(sorted(FAULTS)) or "none yet"
        raise UsageError(f"unknown fault variant(s) {', '.join(unknown)} (known: {known})")
    return chosen


def type1_link(
    faults: frozenset[str],
    profile: FrameProfile | str,
    config: LinkConfig | None,
    name: str,
    state_provider: StateProvider | None,
) -> Type1Link:
    return Type1Link(profile, config, name, state_provider=state_provider)
