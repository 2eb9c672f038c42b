"""The dissector of the shipped profiles, written once by the CLI for every test here."""

from __future__ import annotations

from pathlib import Path

import pytest

from .harness import make_dissector


@pytest.fixture(scope="session")
def lua(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_dissector(tmp_path_factory.mktemp("dissector") / "ktcs.lua")
