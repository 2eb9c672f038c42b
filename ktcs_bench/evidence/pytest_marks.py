"""`@pytest.mark.requirement("ID", ...)`: a Python test names the requirements it verifies. At
collection every id is checked against the shipped catalogue (an unknown one stops the run, named
with its test), and each becomes a `requirement` property of the test's JUnit testcase -- the
property the bench's own reports write (`junit.REQUIREMENT`) -- so `ktcs-bench trace` reads
pytest's `--junitxml` like any other result. Imported by the tests' conftest; pytest is a test
tool, never imported by the package at run time."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from ktcs_bench.errors import ConfigError
from ktcs_bench.evidence.catalogue import shipped_catalogue
from ktcs_bench.junit import REQUIREMENT

MARK = "requirement"


def marked_ids(item: pytest.Item) -> list[str]:
    """The requirement ids of every `requirement` mark on `item` (its class's and module's too)."""
    return [str(i) for mark in item.iter_markers(MARK) for i in mark.args]


def mark_requirements(items: Sequence[pytest.Item]) -> None:
    """Check each test's requirement ids and record them as its JUnit properties."""
    catalogue = None
    for item in items:
        ids = marked_ids(item)
        if not ids:
            continue
        if catalogue is None:
            catalogue = shipped_catalogue()
        try:
            catalogue.check_ids(ids, item.nodeid, "@pytest.mark.requirement")
        except ConfigError as exc:
            raise pytest.UsageError(str(exc)) from None
        item.user_properties.extend((REQUIREMENT, i) for i in dict.fromkeys(ids))
