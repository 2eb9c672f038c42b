"""Real emulator processes for the conformance tests: started in their own process group, read
up to their JSON ready line, and killed (the whole group) at teardown."""

from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

CLI = [sys.executable, "-m", "ktcs_bench.cli.main"]
READY_TIMEOUT = 20.0


class Proc:
    def __init__(self, args: list[str], log: Path) -> None:
        self.args = args
        self.log = log
        self._err = log.open("wb")
        self.p = subprocess.Popen(
            [*CLI, *args], stdout=subprocess.PIPE, stderr=self._err, start_new_session=True
        )
        self.ready: dict[str, Any] = {}

    def wait_ready(self) -> dict[str, Any]:
        assert self.p.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(self.p.stdout, selectors.EVENT_READ)
        end = time.monotonic() + READY_TIMEOUT
        line = b""
        while not line.endswith(b"\n"):
            if time.monotonic() > end or self.p.poll() is not None:
                raise AssertionError(f"{self.args} not ready: {self.stderr()}")
            if sel.select(0.1):
                chunk = os.read(self.p.stdout.fileno(), 4096)
                if not chunk:
                    raise AssertionError(f"{self.args} closed stdout: {self.stderr()}")
                line += chunk
        sel.close()
        self.ready = json.loads(line.decode().splitlines()[0])
        return self.ready

    def stderr(self) -> str:
        self._err.flush()
        return self.log.read_text(errors="replace")[-3000:]

    def stop(self) -> None:
        if self.p.poll() is None:
            try:
                os.killpg(self.p.pid, signal.SIGTERM)
                self.p.wait(5)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(self.p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.p.wait(5)
        if self.p.stdout is not None:
            self.p.stdout.close()
        self._err.close()


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., Proc]]:
    """spawn("emulator", "atc", ...) -> a started process (ready line read unless wait=False)."""
    procs: list[Proc] = []

    def start(*args: str, wait: bool = True) -> Proc:
        proc = Proc(list(args), tmp_path / f"proc{len(procs)}.log")
        procs.append(proc)
        if wait:
            proc.wait_ready()
        return proc

    yield start
    for proc in reversed(procs):
        proc.stop()


def cli(*args: str, timeout: float = 90.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
