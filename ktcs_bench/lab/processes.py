"""Child processes of a lab: start a device with its command line, read its ready line, watch it,
stop it (SIGTERM, then SIGKILL after a grace period), restart it with the same arguments.

Every child holds the read end of a pipe whose write end only its launcher holds (`--lifeline`):
when the launcher ends, however it ends (SIGKILL included), the kernel closes the write end, the
child reads end of file and stops. A device never outlives the lab that started it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import msgspec

from ktcs_bench.errors import PeerError
from ktcs_bench.messages import ReadyLine
from ktcs_bench.runtime import process_started

READY_TIMEOUT = 30.0
STOP_GRACE = 5.0


@dataclass
class Child:
    name: str
    argv: list[str]
    log_path: Path
    proc: subprocess.Popen[bytes] | None = None
    ready: ReadyLine = field(default_factory=lambda: ReadyLine())
    starts: int = 0
    exit_code: int | None = None
    started: int | None = None  # the process's start time (runtime.process_started)
    _log: IO[bytes] | None = None
    _lifeline: int | None = None  # our end of the child's lifeline pipe

    def start(self, env: dict[str, str] | None = None) -> ReadyLine:
        """Start and wait for the ready line; PeerError if it dies, stays silent or says why it
        cannot start (`{"error": ...}`, e.g. its port is taken)."""
        self.stop()  # what is left of a previous run (its pipes, its log file)
        self._log = open(self.log_path, "ab")  # noqa: SIM115 -- lives as long as the child
        theirs, self._lifeline = os.pipe()  # both ends close-on-exec; pass_fds opens theirs
        try:
            self.proc = subprocess.Popen(
                [*self.argv, "--lifeline", str(theirs)], stdout=subprocess.PIPE, stderr=self._log,
                stdin=subprocess.DEVNULL, env=env, start_new_session=True, pass_fds=(theirs,),
            )  # fmt: skip
        finally:
            os.close(theirs)
        self.started = process_started(self.proc.pid)
        self.starts += 1
        self.exit_code = None
        line = _readline(self.proc, READY_TIMEOUT)
        try:
            ready = json.loads(line) if line else None
        except ValueError:
            ready = None
        if not isinstance(ready, dict) or "error" in ready:
            code = self.proc.poll()
            self.stop()
            if isinstance(ready, dict):
                raise PeerError(f"{self.name} did not start: {ready['error']}")
            tail = _tail(self.log_path)
            raise PeerError(f"{self.name} did not start (exit {code}); its log ends:\n{tail}")
        try:
            self.ready = msgspec.convert(ready, ReadyLine)
        except msgspec.ValidationError as exc:
            self.stop()
            raise PeerError(
                f"{self.name} started with a ready line not understood: {exc}"
            ) from None
        # keep draining stdout so the child never blocks on a full pipe
        threading.Thread(target=_drain, args=(self.proc,), daemon=True).start()
        return self.ready

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def poll(self) -> int | None:
        """The exit code if it has exited since the last poll (a crash to report), else None."""
        if self.proc is None or self.exit_code is not None:
            return None
        code = self.proc.poll()
        if code is not None:
            self.exit_code = code
        return code

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(STOP_GRACE)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        if self.proc is not None and self.proc.stdout is not None:
            self.proc.stdout.close()
        if self._log is not None:
            self._log.close()
            self._log = None
        if self._lifeline is not None:
            os.close(self._lifeline)
            self._lifeline = None

    def kill(self) -> None:
        """SIGKILL, as a crash would (tests and `lab kill`)."""
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()


def _readline(proc: subprocess.Popen[bytes], timeout: float) -> str | None:
    assert proc.stdout is not None
    result: list[bytes] = []
    t = threading.Thread(target=lambda: result.append(proc.stdout.readline()), daemon=True)  # type: ignore[union-attr]
    t.start()
    t.join(timeout)
    if not result or not result[0]:
        return None
    return result[0].decode(errors="replace")


def _drain(proc: subprocess.Popen[bytes]) -> None:
    try:
        while proc.stdout is not None and proc.stdout.read(65536):
            pass
    except (OSError, ValueError):
        pass


def _tail(path: Path, lines: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


def emulator_argv(*args: str) -> list[str]:
    return [sys.executable, "-m", "ktcs_bench.cli.main", "emulator", *args]


def wait_for(predicate: Any, timeout: float, step: float = 0.05) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return bool(predicate())
