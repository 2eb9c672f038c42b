"""Issue 13 item 2: a lab that dies however it dies (SIGKILL of `lab up`) takes its devices with
it, leaves no dead taps listed, and `lab down` and the next `lab up` clean up whatever it left; a
port that is taken is said so (exit 3), never a traceback."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
from pathlib import Path

from ktcs_bench.runtime import process_alive

from .conftest import lab_file, start_lab


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cli(run_dir: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args], capture_output=True, text=True,
        timeout=180, env={**os.environ, "KTCS_BENCH_RUN_DIR": str(run_dir)},
    )  # fmt: skip


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    """Wait on each process (a pidfd turns readable when it ends); the pids still running."""
    poll, fds = select.poll(), {}
    for pid in pids:
        try:
            fd = os.pidfd_open(pid)
        except ProcessLookupError:
            continue  # ended and reaped already
        fds[fd] = pid
        poll.register(fd, select.POLLIN)
    left = dict(fds)
    try:
        end = timeout * 1000
        while left and end > 0:
            for fd, _ in poll.poll(200):
                poll.unregister(fd)
                left.pop(fd, None)
            end -= 200
        return sorted(left.values())
    finally:
        for fd in fds:
            os.close(fd)


def lab_processes(path: Path) -> list[int]:
    """Processes whose command line names this lab file (every device of a lab does)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if str(path).encode() in cmdline and process_alive(int(entry.name)):
                out.append(int(entry.name))
    return out


def test_sigkill_of_lab_up_ends_every_device_and_the_lab_can_start_again(tmp_path: Path) -> None:
    port = free_port()
    run_dir = tmp_path / "run"
    with start_lab(tmp_path, "deadlab", console_port=port) as lab:
        devices = lab.state()["devices"]
        pids = [int(d["pid"]) for d in devices.values()]
        assert len(pids) == 11
        # a tap in every link: each station's three and the two interval links between IXLs
        assert len(cli(run_dir, "tap", "list").stdout.splitlines()) == 11
        os.kill(lab.proc.pid, signal.SIGKILL)
        lab.proc.wait(10)
        assert wait_gone(pids, 30) == [], "devices outlived their lab"
        listed = cli(run_dir, "tap", "list")
        assert listed.returncode == 0 and listed.stdout == "", listed.stdout
        assert not list((run_dir / "taps").glob("*.json"))
        status = cli(run_dir, "lab", "status", "deadlab")
        assert status.returncode == 3 and "died" in status.stderr, status.stderr
        assert "Traceback" not in status.stderr
        down = cli(run_dir, "lab", "down", "deadlab")
        assert down.returncode == 0, down.stderr
        assert "had died" in down.stdout and "Traceback" not in down.stderr
        assert not (run_dir / "labs" / "deadlab" / "lab.json").exists()
        again = cli(run_dir, "lab", "down", "deadlab")
        assert again.returncode == 2 and "not running" in again.stderr, again.stderr
    with start_lab(tmp_path, "deadlab", console_port=port) as lab:  # same file, same console port
        assert lab.state()["devices"]["ctc"]["console"] == f"http://127.0.0.1:{port}/"
        down = cli(run_dir, "lab", "down", "deadlab")
        assert down.returncode == 0 and "stopped" in down.stdout, down.stdout + down.stderr
        assert lab.proc.wait(30) == 0
        assert lab_processes(lab_file(tmp_path, "deadlab")) == []


def test_next_lab_up_stops_what_a_dead_lab_left_running(tmp_path: Path) -> None:
    port = free_port()
    with start_lab(tmp_path, "leftlab", console_port=port) as lab:
        ctc = lab.state()["devices"]["ctc"]
        others = [int(d["pid"]) for n, d in lab.state()["devices"].items() if n != "ctc"]
        os.kill(ctc["pid"], signal.SIGSTOP)  # a hung device: it cannot see its lab die
        os.kill(lab.proc.pid, signal.SIGKILL)
        lab.proc.wait(10)
        assert wait_gone(others, 30) == []
        assert process_alive(ctc["pid"], ctc["started"]), "the hung CTC still holds its ports"
        with start_lab(tmp_path, "leftlab", console_port=port) as again:
            assert not process_alive(ctc["pid"], ctc["started"])
            assert again.state()["devices"]["ctc"]["console"] == f"http://127.0.0.1:{port}/"
            said = (tmp_path / "leftlab.stderr").read_text()
            assert "stopped what it left running: ctc" in said, said


def test_a_port_taken_is_said_so_and_nothing_is_left_behind(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        path = lab_file(tmp_path, "busylab", console_port=port)
        run = cli(run_dir, "lab", "up", str(path), "--json")
    assert run.returncode == 3, run.stderr
    assert "Traceback" not in run.stderr and 'File "' not in run.stderr, run.stderr
    assert "ctc did not start" in run.stderr and f"{port}" in run.stderr, run.stderr
    assert "address already in use" in run.stderr.lower(), run.stderr
    assert not (run_dir / "labs" / "busylab" / "lab.json").exists()
    assert cli(run_dir, "tap", "list").stdout == ""
    assert lab_processes(path) == []
