"""Every tap test must leave no fd and no thread behind."""

import pytest


@pytest.fixture(autouse=True)
def _no_leaks(leak_check: None) -> None:
    """Switch the shared leak check (tests/conftest.py) on for this folder."""
