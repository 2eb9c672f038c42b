"""Every transport test must leave no fds and no threads behind."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest


def _fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    fds, threads = _fds(), set(threading.enumerate())
    yield
    for _ in range(50):  # writer threads finish their join within close(); allow a moment
        leaked_threads = set(threading.enumerate()) - threads
        if not leaked_threads:
            break
        time.sleep(0.02)
    assert not leaked_threads, leaked_threads
    assert _fds() - fds == set(), "file descriptors leaked"
