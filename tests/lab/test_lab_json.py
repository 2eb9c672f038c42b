"""What a lab writes as JSON -- `lab simulate`'s summary.json and events.jsonl, `lab status
--json` -- carries the values a JSON reader expects: an enum as its value ("normal", "set"), never
Python's text of it ("Status.NORMAL"); and each link going up or down is one event at each end."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ktcs_bench.ixl.routes import RouteStatus
from ktcs_bench.train.supervision import Status
from tests.lab.conftest import lab_file

ENUM_TEXT = re.compile(r"[A-Z][A-Za-z]*\.[A-Z][A-Z_]*")  # "Status.NORMAL", "RouteStatus.SET"
ATP_STATUS = {s.value for s in Status}
ROUTE_STATUS = {s.value for s in RouteStatus}


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", *args],
                          capture_output=True, text=True, env=env, timeout=300)  # fmt: skip


def _strings(obj: Any, path: str = "") -> Iterator[tuple[str, str]]:
    """Every string in a JSON document (keys too), with where it is."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield f"{path}/{k} (key)", str(k)
            yield from _strings(v, f"{path}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _strings(v, f"{path}[{i}]")
    elif isinstance(obj, str):
        yield path, obj


def _enum_texts(obj: Any) -> list[tuple[str, str]]:
    return [(where, s) for where, s in _strings(obj) if ENUM_TEXT.fullmatch(s)]


def test_simulate_summary_and_events_carry_enum_values_not_their_python_text(
    tmp_path: Path,
) -> None:
    run_ = _cli("lab", "simulate", "reference", "--for", "30", "--out", str(tmp_path))
    assert run_.returncode == 0, run_.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["trains"]["train1001"]["status"] in ATP_STATUS, summary["trains"]
    assert _enum_texts(summary) == []
    events = [json.loads(e) for e in (tmp_path / "events.jsonl").read_text().splitlines()]
    assert _enum_texts(events) == []
    # what it printed of each train is the same JSON
    assert "Status." not in run_.stdout, run_.stdout


def test_lab_status_json_carries_enum_values_not_their_python_text(tmp_path: Path) -> None:
    """`lab status --json` of a running lab (in one process, on real sockets): the trains' ATP
    status and the interlockings' route states are values."""
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}
    path = lab_file(tmp_path, "jsonlab", trains=True)
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(path), "--in-process",
         "--speed", "5", "--json", "--interval", "3600"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        first = json.loads(proc.stdout.readline() or "{}")
        assert first.get("lab") == "jsonlab", first
        deadline = time.monotonic() + 120
        while True:  # until train 1001 is on the line under its ATP and the IXLs report routes
            run_ = _cli("lab", "status", "jsonlab", "--json", env=env)
            assert run_.returncode == 0, run_.stderr
            status = json.loads(run_.stdout)
            devices = {n: d["status"] or {} for n, d in status["devices"].items()}
            if devices["train1001"].get("status") and devices["ixl18"].get("routes"):
                break
            assert time.monotonic() < deadline, devices["train1001"]
            time.sleep(0.5)
        assert devices["train1001"]["status"] in ATP_STATUS, devices["train1001"]
        for st in (18, 20, 22):
            routes = devices[f"ixl{st}"]["routes"]
            assert routes and set(routes.values()) <= ROUTE_STATUS, routes
        assert _enum_texts(status) == []
        assert _cli("lab", "down", "jsonlab", env=env).returncode == 0
        assert proc.wait(30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_simulate_logs_each_link_going_up_once_at_each_end(tmp_path: Path) -> None:
    """The reference lab's eleven links come up once: at the IXL end each (atc, io, ctc), at
    the ATC's and trackside's end of the Type I ones, and at both IXLs of each interval link (as
    `east` at its west end, `west` at the other) -- one event a transition, not two."""
    run_ = _cli("lab", "simulate", "reference", "--for", "10", "--out", str(tmp_path))
    assert run_.returncode == 0, run_.stderr
    events = [json.loads(e) for e in (tmp_path / "events.jsonl").read_text().splitlines()]
    links = Counter(  # while the lab runs (the lab's end takes the CTC link down)
        (e["device"], e["text"]) for e in events if e["kind"] == "link" and e["t"] < 10
    )
    want: Counter[tuple[str, str]] = Counter()
    for st in (18, 20, 22):
        want.update({(f"ixl{st}", f"{role} link up"): 1 for role in ("atc", "io", "ctc")})
        want.update({(f"{dev}{st}", "IXL link up"): 1 for dev in ("atc", "io")})
    for west, east in ((18, 20), (20, 22)):  # the neighbouring IXLs (SPEC §6.6)
        want.update({(f"ixl{west}", "east link up"): 1, (f"ixl{east}", "west link up"): 1})
    assert links == want
