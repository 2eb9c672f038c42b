"""An interrupted `test run` (Ctrl-C or SIGTERM) ends quietly with 130 (143 on SIGTERM) and its reports: the
procedure it was in is an error "interrupted", the ones it never reached are skipped, and the
JUnit says so to a CI (issue 21 item 2). A real `ktcs-bench` process on the virtual clock (the
live one: tests/procedure/test_live.py). And a live lab's connection cut short by an interrupt
is not read again as if its answer were the next request's."""

from __future__ import annotations

import asyncio
import json
import os
import selectors
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.lab.access_live import LiveLabAccess

SHIPPED = data_dir("emulators") / "procedures"

LONG = """\
id: long-wait
title: cut a link, then wait a whole day of the lab's clock, the timetable's trains running
setup: {lab: reference}
steps:
  - fault: link st20-io cut
  - wait: 24h
"""

NOISE = ("Traceback", "Event loop is closed", "Task was destroyed", "Exception ignored",
         "Error")  # fmt: skip


def read_until(proc: subprocess.Popen[bytes], wanted: str, limit: float = 300) -> str:
    """The process's stdout up to the line that starts with `wanted`, read unbuffered (what
    follows is left to `communicate`); AssertionError if it ends or is silent `limit` s first."""
    assert proc.stdout is not None
    text, line = "", b""
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        while True:
            assert sel.select(limit), f"no line {wanted!r} yet: {text + line.decode()}"
            byte = os.read(proc.stdout.fileno(), 1)
            assert byte, f"the run ended before {wanted!r}: {text + line.decode()}"
            line += byte
            if byte == b"\n":
                text += line.decode()
                if line.decode().startswith(wanted):
                    return text
                line = b""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_run_is_quiet_writes_its_reports_and_exits_128_plus_the_signal(
    tmp_path: Path, sig: signal.Signals
) -> None:
    long = tmp_path / "long.yaml"
    long.write_text(LONG, encoding="utf-8")
    junit, report = tmp_path / "j.xml", tmp_path / "not" / "yet" / "there"
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "test", "run", "--no-colour",
         str(SHIPPED / "route_set.yaml"), str(long), str(SHIPPED / "sequential_release.yaml"),
         "--junit", str(junit), "--report", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        out = read_until(proc, "PASS  route-set")  # the first is done: the run is on to the next
        proc.send_signal(sig)
        rest, errb = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    out, err = out + rest.decode(), errb.decode()
    assert proc.returncode == 128 + sig, out + err  # 130 Ctrl-C, 143 SIGTERM
    assert not [w for w in NOISE if w in err], err
    assert err.splitlines() == ["1 of 3 procedures passed, 1 in error, 1 not run (interrupted)"]
    assert "ERROR long-wait:" in out and "      interrupted " in out
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None
    counts = {k: suite.get(k) for k in ("tests", "failures", "errors", "skipped")}
    assert counts == {"tests": "3", "failures": "0", "errors": "1", "skipped": "1"}
    cases = {c.get("name"): c for c in suite.findall("testcase")}
    error = cases["long-wait"].find("error")
    assert error is not None and (error.get("message") or "").startswith("interrupted")
    outcome = [c.tag for c in cases["route-set"] if c.tag != "properties"]  # its requirement ids
    assert outcome == ["system-out"]  # no failure, no error: its steps' output only
    skipped = cases["sequential-release"].find("skipped")
    assert skipped is not None and "interrupted" in (skipped.get("message") or "")
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    assert results["summary"] == {"pass": 1, "fail": 0, "error": 1, "skipped": 1}
    assert {"index.html", "route-set.html", "long-wait.html"} <= {p.name for p in report.iterdir()}
    assert "interrupted" in (report / "long-wait.html").read_text(encoding="utf-8")


def test_a_request_cut_short_does_not_leave_its_answer_for_the_next(tmp_path: Path) -> None:
    """A device's control port that answers the first request only after the test lets it: the
    request is cancelled (as an interrupt cancels it) while it waits, and the next request gets
    its own answer, not the first one's."""

    async def main() -> tuple[dict[str, object], dict[str, object]]:
        got_first, let_go = asyncio.Event(), asyncio.Event()

        async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            while line := await reader.readline():
                cmd = json.loads(line)["cmd"]
                if cmd == "first":
                    got_first.set()
                    await let_go.wait()
                writer.write(json.dumps({"ok": True, "answer_to": cmd}).encode() + b"\n")
                await writer.drain()

        server = await asyncio.start_server(serve, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        state = {"devices": {"dev": {"kind": "ctc", "control": f"127.0.0.1:{port}"}}}
        access = LiveLabAccess("nolab", state, "token")
        try:
            first = asyncio.ensure_future(access.device("dev", {"cmd": "first"}))
            await got_first.wait()
            first.cancel()
            with pytest.raises(asyncio.CancelledError):
                await first
            let_go.set()  # the first answer is sent now, on the connection it came on
            second = await access.device("dev", {"cmd": "second"})
            third = await access.device("dev", {"cmd": "third"})
        finally:
            await access.close()
            server.close()
        return second, third

    second, third = asyncio.run(main())
    assert second["answer_to"] == "second" and third["answer_to"] == "third"
