"""Issue 21 item 12: a console flood must not starve the lab. One websocket sends 10,000 route
requests to the CTC's web console, as fast as it can; meanwhile `/api/state` is polled.

Two labs, each the reference lab with its timetable trains running under ARS:

* in one process (`lab up --in-process --speed 5`): the console shares the loop with every device,
  whose clock runs five times the wall's (a Type II link's T_MAX of 3 s is 0.6 s of wall time);
* live (`lab up`): the CTC and its console in a process of their own.

For each: `/api/state` latency (median, max) for BASELINE_S without the flood and then during it
(from the first request until every request is answered, at least FLOOD_S), the links dropped
during the flood (Type II reconnections at the taps, Type I links the IXLs report in
communication error; beside them the CTC links the IXLs logged going down), the answers the
console gave (results by reason, and "busy"), and the trains' emergency brakes during it. Goal:
no link dropped, no emergency brake, the excess answered busy, `/api/state` as quick as without
the flood.

    .venv/bin/python benchmarks/console_flood.py [--requests 10000] [--only in-process|live]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiohttp

from ktcs_bench.datafiles import data_dir
from ktcs_bench.runtime import read_token
from ktcs_bench.transport import jsonlines

BASELINE_S = 10.0  # /api/state polled without the flood
FLOOD_S = 15.0  # polled at least this long from the flood's first request
POLL_S = 0.1  # between two /api/state requests
READY_S = 90.0
ROUTES = [(18, "01", "11"), (20, "01", "11"), (22, "01", "11")]


@dataclass
class Lab:
    name: str
    proc: subprocess.Popen[str]
    run_dir: Path
    state: dict[str, Any] = field(default_factory=dict)
    token: str = ""

    @property
    def console(self) -> str:
        return str(self.state["devices"]["ctc"]["console"])

    async def request(self, address: str, obj: dict[str, Any]) -> dict[str, Any]:
        host, _, port = address.rpartition(":")
        return await jsonlines.request(host, int(port), obj, timeout=30, token=self.token)

    async def device(self, name: str, obj: dict[str, Any]) -> dict[str, Any]:
        return await self.request(str(self.state["devices"][name]["control"]), obj)


def lab_file(tmp: Path, name: str) -> Path:
    """The shipped reference lab (timetable, trains, ARS) renamed, its console on a free port."""
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text(encoding="utf-8")
    for key, folder in (("line", "lines"), ("timetable", "timetables")):
        path = (data_dir("emulators") / folder / "reference.yaml").resolve()
        text = text.replace(f"{key}: ../{folder}/reference.yaml", f"{key}: {path}")
    text = text.replace("lab: reference", f"lab: {name}").replace("port: 8020", "port: 0")
    path = tmp / f"{name}.yaml"
    path.write_text(text, encoding="utf-8")
    return path


@contextlib.contextmanager
def start_lab(in_process: bool) -> Iterator[Lab]:
    tmp = Path(tempfile.mkdtemp(prefix="ktcs-console-flood-"))
    name = "floodip" if in_process else "floodlive"
    argv = [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(lab_file(tmp, name)),
            "--json", "--interval", "30"]  # fmt: skip
    if in_process:
        argv += ["--in-process", "--speed", "5"]
    stderr = open(tmp / "stderr", "w")  # noqa: SIM115 -- closed below
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=stderr, text=True, start_new_session=True,
        env={**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp / "run")},
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        if not proc.stdout.readline():
            raise SystemExit(f"lab up failed: {(tmp / 'stderr').read_text()[-2000:]}")
        threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
        lab = Lab(name, proc, tmp / "run")
        lab.state = json.loads((lab.run_dir / "labs" / name / "lab.json").read_text())
        lab.token = read_token(Path(lab.state["token_file"]))
        yield lab
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        stderr.close()


async def ready(lab: Lab) -> None:
    """Every station synced at the CTC in center mode, its link up, its points detected."""
    end = time.monotonic() + READY_S
    while time.monotonic() < end:
        with contextlib.suppress(OSError, TimeoutError, ValueError):
            stations = (await lab.device("ctc", {"cmd": "status"}))["status"]["stations"]
            if stations and all(
                s["link"] == "up" and s["synced"] and s["mode"] == "center"
                and "failed" not in s["points"].values()
                for s in stations.values()
            ):  # fmt: skip
                return
        await asyncio.sleep(0.5)
    raise SystemExit(f"lab {lab.name} not ready within {READY_S:g} s")


async def health(lab: Lab) -> dict[str, int]:
    """Counters whose growth is harm: Type II connections made at each tap, Type I links each IXL
    reported in communication error, each train's emergency brakes, devices not alive."""
    status = (await lab.request(str(lab.state["control"]), {"cmd": "status"}))["status"]
    out: dict[str, int] = {}
    for name, tap in status["taps"].items():
        if "connections" in tap:
            out[f"type2 {name}"] = int(tap["connections"])
    for name, dev in status["devices"].items():
        st = dev.get("status") or {}
        if not dev.get("alive"):
            out[f"dead {name}"] = 1
        if st.get("kind") == "train":
            out[f"eb {name}"] = int(st.get("emergency_brakes") or 0)
        if st.get("kind") == "ixl":
            events = (await lab.device(name, {"cmd": "events", "last": 2000}))["events"]
            for e in events:
                if e["kind"] == "link" and "communication error" in e["text"]:
                    out[f"type1 {name}"] = out.get(f"type1 {name}", 0) + 1
                if e["kind"] == "link" and "ctc link down" in e["text"]:
                    out[f"ctcdown {name}"] = out.get(f"ctcdown {name}", 0) + 1
    return out


def grown(before: dict[str, int], after: dict[str, int], prefix: str) -> int:
    return sum(max(0, v - before.get(k, 0)) for k, v in after.items() if k.startswith(prefix))


async def poll(session: aiohttp.ClientSession, url: str, until: asyncio.Event) -> list[float]:
    """/api/state, one request at a time, POLL_S apart, until `until` is set; each latency."""
    out = []
    while not until.is_set():
        t0 = time.monotonic()
        async with session.get(url + "api/state") as r:
            await r.read()
        out.append(time.monotonic() - t0)
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(until.wait(), POLL_S)
    return out


async def flood(session: aiohttp.ClientSession, url: str, count: int) -> Counter[str]:
    """`count` route requests on one websocket as fast as it takes them; the answers by kind."""
    answers: Counter[str] = Counter()
    ws = await session.ws_connect(url + "ws")
    done = asyncio.Event()

    async def read() -> None:
        async for msg in ws:
            if msg.type != aiohttp.WSMsgType.TEXT:
                continue
            data = json.loads(msg.data)
            kind = data.get("type")
            if kind == "result":
                answers["accepted" if data.get("ok") else f"not: {data.get('reason')}"] += 1
            elif kind == "busy":
                answers["busy"] += 1
            else:
                continue
            if sum(answers.values()) >= count:
                done.set()

    reader = asyncio.create_task(read())
    for i in range(count):
        station, entry, exit_ = ROUTES[i % len(ROUTES)]
        await ws.send_str(json.dumps({"type": "route_set", "station": station, "entry": entry,
                                      "exit": exit_, "id": i}))  # fmt: skip
        if i % 100 == 99:
            await asyncio.sleep(0)  # let this process's poller run too
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(done.wait(), 180)
    await ws.close()
    reader.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await reader
    return answers


def figures(latencies: list[float]) -> str:
    if not latencies:
        return "no answer"
    return (f"median {statistics.median(latencies) * 1e3:.1f} ms, max {max(latencies) * 1e3:.1f} "
            f"ms over {len(latencies)} requests")  # fmt: skip


async def measure(lab: Lab, count: int) -> dict[str, Any]:
    await ready(lab)
    url = lab.console
    async with aiohttp.ClientSession() as session:
        stop = asyncio.Event()
        poller = asyncio.create_task(poll(session, url, stop))
        await asyncio.sleep(BASELINE_S)
        stop.set()
        quiet = await poller
        before = await health(lab)
        stop = asyncio.Event()
        poller = asyncio.create_task(poll(session, url, stop))
        t0 = time.monotonic()
        answers = await flood(session, url, count)
        answered_s = time.monotonic() - t0
        await asyncio.sleep(max(0.0, FLOOD_S - answered_s))
        stop.set()
        during = await poller
        after = await health(lab)
    return {"quiet": quiet, "during": during, "answers": answers, "answered_s": answered_s,
            "type2": grown(before, after, "type2 "), "type1": grown(before, after, "type1 "),
            "ctcdown": grown(before, after, "ctcdown "),
            "eb": grown(before, after, "eb "), "dead": grown(before, after, "dead ")}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--requests", type=int, default=10_000)
    ap.add_argument("--only", choices=("in-process", "live"))
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    for in_process in (True, False):
        label = "in-process lab (speed 5)" if in_process else "live lab (CTC its own process)"
        if args.only and (args.only == "in-process") != in_process:
            continue
        with start_lab(in_process) as lab:
            r = asyncio.run(measure(lab, args.requests))
        answers = r["answers"]
        dropped = r["type2"] + r["type1"]
        print(f"{label}: {args.requests} route requests on one websocket, all answered in "
              f"{r['answered_s']:.1f} s")  # fmt: skip
        print(f"  /api/state without the flood: {figures(r['quiet'])}")
        print(f"  /api/state during the flood:  {figures(r['during'])}")
        print(f"  links dropped: {dropped} (Type II reconnections {r['type2']}, Type I links in "
              f"communication error {r['type1']}; goal 0); CTC links the IXLs logged down "
              f"{r['ctcdown']}; devices died: {r['dead']}")  # fmt: skip
        print(
            f"  answers: busy {answers.get('busy', 0)}, "
            + ", ".join(f"{k} {v}" for k, v in sorted(answers.items()) if k != "busy")
        )
        print(f"  emergency brakes during the flood: {r['eb']} (goal 0)")


if __name__ == "__main__":
    main()
