"""A real lab for the tests: `ktcs-bench lab up` as a subprocess, every device its own process,
Type I over paced ptys through taps, Type II over TCP through taps."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.runtime import client_token, read_token, token_file_for
from tests.console.conftest import browser_context  # noqa: F401 -- headless Chromium, for the console test

ROOT = Path(__file__).resolve().parents[2]


RUN_DIRS: list[Path] = []  # the run folders of the labs started here (their tokens are there)


def token_for(address: str) -> str | None:
    """The token of the port at `address`: its lab's (a lab started here), else the one the
    package's own clients would present (the user's, for a device run on its own)."""
    host, _, port = address.rpartition(":")
    for folder in RUN_DIRS:
        found = token_file_for((host, int(port)), folder)
        if found is not None:
            return read_token(found)
    return client_token((host, int(port)))


def request(
    address: str, obj: dict[str, Any], timeout: float = 20.0, token: str | None = None
) -> dict[str, Any]:
    """One command to a device's JSON-lines control port (plain blocking socket: it works beside
    any event loop, Playwright's included), with the port's token (`token_for`) unless given."""
    host, _, port = address.rpartition(":")
    given = token if token is not None else token_for(address)
    with socket.create_connection((host, int(port)), timeout=timeout) as sock:
        sock.sendall(json.dumps({**obj, "token": given} if given else obj).encode() + b"\n")
        line = sock.makefile("rb").readline()
    if not line:
        raise ConnectionError(f"{address} closed without answering")
    return json.loads(line)  # type: ignore[no-any-return]


def stop_group(proc: subprocess.Popen[Any], grace: float) -> None:
    """End a process started in its own session, and all it started: SIGTERM to its group, then
    SIGKILL if it has not ended within `grace` seconds."""
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def wait_until(what: str, predicate: Callable[[], Any], timeout: float = 30.0) -> Any:
    end = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < end:
        last = predicate()
        if last:
            return last
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for: {what} (last: {last!r})")


class RunningLab:
    def __init__(self, proc: subprocess.Popen[str], first: dict[str, Any], run_dir: Path) -> None:
        self.proc, self.info, self.run_dir = proc, first, run_dir
        self.control = first["control"]
        self.links = {e["link"]: e for e in first["links"]}

    def state(self) -> dict[str, Any]:
        return json.loads((self.run_dir / "labs" / self.info["lab"] / "lab.json").read_text())

    def device(self, name: str) -> str:
        return str(self.state()["devices"][name]["control"])

    def status(self, name: str) -> dict[str, Any]:
        answer = request(self.device(name), {"cmd": "status"})
        return answer["status"]  # type: ignore[no-any-return]

    def ctc(self, obj: dict[str, Any]) -> dict[str, Any]:
        return request(self.device("ctc"), obj)

    def lab(self, obj: dict[str, Any]) -> dict[str, Any]:
        return request(self.control, obj, timeout=60)

    def cli(
        self, *args: str, timeout: float = 60, env: dict[str, str] | None = None
    ) -> subprocess.CompletedProcess[str]:
        """`ktcs-bench ARGS` against this lab (its run folder), with `env` added."""
        return subprocess.run(
            [sys.executable, "-m", "ktcs_bench.cli.main", *args], capture_output=True, text=True,
            timeout=timeout,
            env={**os.environ, "KTCS_BENCH_RUN_DIR": str(self.run_dir), **(env or {})},
        )  # fmt: skip


def without_trains(text: str) -> str:
    """A lab file's text without its timetable, the train devices that run it and the CTC's
    automatic route setting over it: an empty line, for tests that place trains of their own
    or need no train at all."""
    kept = [
        ln
        for ln in text.splitlines(keepends=True)
        if not ln.startswith(("timetable:", "ars:")) and "{kind: train," not in ln
    ]
    return "".join(kept)


def lab_file(
    tmp: Path,
    name: str,
    extra_devices: str = "",
    console_port: int = 0,
    origins: str = "",
    trains: bool = False,
) -> Path:
    """The shipped reference lab under another name, with the console on `console_port` (default
    any free port) taking pages from `origins` too (a YAML list), and `extra_devices`, YAML lines
    added under `devices:`. Its timetable trains run only with `trains`: most tests need the
    line empty (`without_trains`)."""
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    if not trains:
        text = without_trains(text)
    timetable = (data_dir("emulators") / "timetables" / "reference.yaml").resolve()
    text = text.replace("timetable: ../timetables/reference.yaml", f"timetable: {timetable}")
    text = text.replace("lab: reference", f"lab: {name}")
    text = text.replace("port: 8020", f"port: {console_port}")
    text = text.replace("origins: []", f"origins: {origins or '[]'}")
    if extra_devices:
        text = text.replace("\nlinks:\n", f"{extra_devices}\nlinks:\n")
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("line: ../lines/reference.yaml", f"line: {line}")
    path = tmp / f"{name}.yaml"
    path.write_text(text, encoding="utf-8")
    return path


@contextlib.contextmanager
def start_lab(
    tmp: Path,
    name: str,
    extra_devices: str = "",
    clear: bool = True,
    console_port: int = 0,
    origins: str = "",
    path: Path | None = None,
    ready: Callable[[RunningLab], Any] | None = None,
    trains: bool = False,
    up_args: tuple[str, ...] = (),
) -> Iterator[RunningLab]:
    """Start a lab (`lab up` with `up_args` added) and wait until every station is synced at the
    CTC in center mode with every point detected (and, with `clear`, the empty line reported
    clear), or until `ready(lab)` holds when given (a lab whose CTC is not its own). The lab is the reference lab renamed `name`
    (`lab_file`, with its timetable trains if `trains`), or the lab file at `path` (whose lab must
    be called `name`)."""
    run_dir = tmp / "run"
    RUN_DIRS.append(run_dir)
    if path is None:
        path = lab_file(tmp, name, extra_devices, console_port, origins, trains)
    stderr = open(tmp / f"{name}.stderr", "w")  # noqa: SIM115 -- closed below
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(path), "--json", "--interval", "5", *up_args],
        stdout=subprocess.PIPE, stderr=stderr, text=True, start_new_session=True,
        env={**os.environ, "KTCS_BENCH_RUN_DIR": str(run_dir)},
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"lab up failed: {(tmp / f'{name}.stderr').read_text()}")
        lab = RunningLab(proc, json.loads(line), run_dir)
        # drain the status stream so the lab never blocks on a full pipe
        import threading

        threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
        # a station syncs at the CTC as soon as its IXL is up, before its field reports: the
        # points read failed (undetected) until the trackside's first indications reach it
        wait_until(
            "every station synced at the CTC, every point detected, the empty line reported clear",
            (lambda: ready(lab))
            if ready is not None
            else lambda: all(
                s["link"] == "up"
                and s["synced"]
                and s["mode"] == "center"
                and "failed" not in s["points"].values()
                and not (clear and s["occupied"])
                for s in lab.ctc({"cmd": "status"})["status"]["stations"].values()
            ),
            timeout=60,
        )
        yield lab
    finally:
        try:
            pids = [d.get("pid") for d in json.loads(
                (run_dir / "labs" / name / "lab.json").read_text())["devices"].values()]  # fmt: skip
        except (OSError, ValueError, KeyError):
            pids = []
        stop_group(proc, 30)
        stderr.close()
        for pid in pids:  # nothing the lab started may outlive it
            if pid:
                try:
                    os.killpg(pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass


@pytest.fixture(scope="module")
def running_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    with start_lab(tmp_path_factory.mktemp("lab"), "testlab") as lab:
        yield lab
