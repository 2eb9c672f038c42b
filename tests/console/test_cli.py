"""`ktcs-bench console --demo-ixls` as a process: prints its URL, serves the page and the state of
three in-process interlockings connected over TCP, and stops cleanly on SIGTERM."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import urllib.request

from ktcs_bench.console.server import STATIC


def test_console_command_serves_the_page_with_connected_stations() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "console", "--demo-ixls"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        url = ""
        for line in proc.stdout:
            if line.startswith("console: "):
                url = line.split()[1]
                break
        assert url.startswith("http://127.0.0.1:"), "no URL printed"
        with urllib.request.urlopen(url, timeout=5) as r:
            assert r.read() == (STATIC / "index.html").read_bytes()
        with urllib.request.urlopen(url + "diagram.svg", timeout=5) as r:
            assert b'id="sig-20-01"' in r.read()
        deadline = time.monotonic() + 15
        while True:
            with urllib.request.urlopen(url + "api/state", timeout=5) as r:
                stations = json.load(r)["stations"]
            if all(s["connected"] and s["synced"] for s in stations.values()):
                break
            assert time.monotonic() < deadline, f"stations never connected: {stations}"
            time.sleep(0.1)
        assert sorted(stations) == ["18", "20", "22"]
        assert stations["18"]["mode"] == "center"
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            rc = proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert rc == 0, proc.stderr.read() if proc.stderr else ""
