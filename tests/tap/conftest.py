"""Every tap test must leave no fd and no thread behind."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest


def _fds() -> set[int]:
    return {int(x) for x in os.listdir("/proc/self/fd")}


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
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
