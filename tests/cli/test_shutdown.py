"""A device stopped while peers are connected ends quietly: no traceback in its log (issue 13
item 9). Real processes, real sockets; the log is the device's stderr, as `lab up` keeps it."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

from tests.lab.conftest import start_lab, token_for


def test_a_device_stopped_with_peers_connected_logs_no_traceback(tmp_path: Path) -> None:
    log = tmp_path / "tc.log"
    with open(log, "w") as stderr:
        proc = subprocess.Popen(
            [sys.executable, "-m", "ktcs_bench.cli.main", "emulator", "trackcircuit",
             "--listen", "127.0.0.1:0", "--verbose"],
            stdout=subprocess.PIPE, stderr=stderr, text=True,
        )  # fmt: skip
    try:
        assert proc.stdout is not None
        ready = json.loads(proc.stdout.readline())
        rails_host, _, rails_port = ready["listen"].rpartition(":")
        control_host, _, control_port = ready["control"].rpartition(":")
        # a rails client that said hello and got the occupancy, and an idle control client: both
        # connections are open, their server tasks waiting for the next line, when the stop comes
        rails = socket.create_connection((rails_host, int(rails_port)), timeout=10)
        control = socket.create_connection((control_host, int(control_port)), timeout=10)
        with rails, control:
            token = token_for(ready["control"])  # the user's: a device run on its own
            hello = {"hello": {"role": "observer", "name": "t"}, "token": token}
            rails.sendall(json.dumps(hello).encode() + b"\n")
            assert b"occupancy" in rails.makefile("rb").readline()
            control.sendall(json.dumps({"cmd": "status", "token": token}).encode() + b"\n")
            assert json.loads(control.makefile("rb").readline())["ok"]
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()  # type: ignore[union-attr]
    text = log.read_text()
    assert "Traceback" not in text and "CancelledError" not in text, text


def test_a_whole_lab_stopped_leaves_no_traceback_in_any_device_log(tmp_path: Path) -> None:
    with start_lab(tmp_path, "quiet", clear=False) as lab:
        logs = lab.run_dir / "labs" / "quiet" / "logs"
        os.killpg(lab.proc.pid, signal.SIGINT)  # Ctrl-C, as the operator stops it
        assert lab.proc.wait(timeout=60) == 130  # interrupted, as every command (issue 21 item 3)
    names = sorted(p.name for p in logs.glob("*.log"))
    assert len(names) == 11, names
    for path in logs.glob("*.log"):
        text = path.read_text()
        assert "Traceback" not in text and "CancelledError" not in text, (path.name, text)
