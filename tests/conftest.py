"""Shared test settings: hypothesis without per-example deadlines (CI machines are slow and
shared), and the leak check that folders using ptys, sockets and threads switch on."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

from ktcs_bench.evidence.pytest_marks import mark_requirements

settings.register_profile(
    "default", deadline=None, suppress_health_check=[HealthCheck.too_slow], print_blob=True
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def _fds() -> set[int]:
    return {int(x) for x in os.listdir("/proc/self/fd")}


@pytest.fixture
def leak_check() -> Iterator[None]:
    """Fail a test that leaves a file descriptor or a thread behind (folders that open ptys,
    sockets and threads turn it on for every test in their conftest)."""
    fds, threads = _fds(), set(threading.enumerate())
    yield
    deadline = time.monotonic() + 10.0  # a leak never ends; a loaded CI machine may be slow
    while time.monotonic() < deadline:
        extra_fds = _fds() - fds
        extra_threads = [t for t in threading.enumerate() if t not in threads and t.is_alive()]
        if not extra_fds and not extra_threads:
            return
        time.sleep(0.02)
    leaked = {
        fd: os.readlink(f"/proc/self/fd/{fd}")
        for fd in extra_fds
        if os.path.exists(f"/proc/self/fd/{fd}")
    }
    assert not leaked and not extra_threads, f"leaked fds {leaked}, threads {extra_threads}"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """`@pytest.mark.requirement` ids: checked against the catalogue, written to JUnit."""
    mark_requirements(items)
