"""The console of a lab in one process (`ktcs-bench lab up --in-process --speed 5`, a real
subprocess: every device on its loop, the console and the control ports on real sockets), with the
reference timetable's trains running under ARS.

Issue 21 item 17: what ARS asks for and why a train waits reach the page's Log panel, live.
Issue 21 item 12: one websocket sending 10,000 route requests had every station's links drop; the
console now answers the excess busy and the lab's links stay up.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import json
import os
import subprocess
import sys
import threading
from collections import Counter
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import aiohttp
import pytest
from playwright.sync_api import expect

from ktcs_bench.runtime import read_token
from tests.lab.conftest import lab_file, request, stop_group, wait_until

T = TypeVar("T")
NAME = "consoleflood"
FLOOD = 10_000
ROUTES = [(18, "01", "11"), (20, "01", "11"), (22, "01", "11")]


class Lab:
    def __init__(self, proc: subprocess.Popen[str], info: dict[str, Any], run_dir: Path) -> None:
        self.proc, self.info = proc, info
        self.console = str(info["console"])
        self.state = json.loads((run_dir / "labs" / NAME / "lab.json").read_text())
        self.token = read_token(Path(self.state["token_file"]))

    def lab(self, obj: dict[str, Any]) -> dict[str, Any]:
        return request(self.info["control"], obj, token=self.token)

    def device(self, name: str, obj: dict[str, Any]) -> dict[str, Any]:
        return request(self.state["devices"][name]["control"], obj, token=self.token)

    def stations(self) -> dict[str, Any]:
        return self.device("ctc", {"cmd": "status"})["status"]["stations"]  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Lab]:
    tmp = tmp_path_factory.mktemp("consoleflood")
    path = lab_file(tmp, NAME, trains=True)  # the console on a free port
    stderr = open(tmp / "stderr", "w")  # noqa: SIM115 -- closed below
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(path), "--in-process",
         "--speed", "5", "--json", "--interval", "5"],
        stdout=subprocess.PIPE, stderr=stderr, text=True, start_new_session=True,
        env={**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp / "run")},
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"lab up failed: {(tmp / 'stderr').read_text()}")
        threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
        running = Lab(proc, json.loads(line), tmp / "run")
        wait_until(
            "every station synced at the CTC in center mode, every point detected",
            lambda: all(
                s["link"] == "up"
                and s["synced"]
                and s["mode"] == "center"
                and "failed" not in s["points"].values()
                for s in running.stations().values()
            ),  # fmt: skip
            timeout=60,
        )
        yield running
    finally:
        stop_group(proc, 30)
        stderr.close()


def in_thread(make: Callable[[], Awaitable[T]], timeout: float = 180) -> T:
    """Run a coroutine on a loop of its own in another thread (the Playwright side keeps this
    thread's)."""
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(lambda: asyncio.run(make())).result(timeout)  # type: ignore[arg-type]


def test_ars_requests_and_waits_reach_the_log_panel_live(browser_context: Any, lab: Lab) -> None:
    page = browser_context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        page.goto(lab.console)
        page.wait_for_selector("#conn.up")
        ars = page.locator("#log .entry.ars")
        # what ARS asked for and what came of it, and why the train waits at the platform
        for text in (
            "ARS: train 1001: requests route 01-11 at station 18",
            "ARS: train 1001: route 01-11 at station 18 accepted",
            "ARS: train 1001 waits for route 11-91 at station 18: dwell until",
        ):
            expect(ars.filter(has_text=text).first).to_be_visible(timeout=60_000)
        # live, as ARS logs it: switched off at station 22 from this page, ARS says so
        button = page.locator("#card-22 button.ars")
        expect(button).to_have_attribute("data-on", "true")
        button.click()
        expect(ars.filter(has_text="ARS: ARS off at station 22").first).to_be_visible()
        button.click()
        expect(ars.filter(has_text="ARS: ARS on at station 22").first).to_be_visible()
    finally:
        page.close()
    assert not errors, f"JavaScript errors on the page: {errors}"
    # the same entries for a page that connects later, and over the HTTP API
    entries = request_state(lab)["log"]
    assert any(e["source"] == "ars" and "requests route 01-11" in e["text"] for e in entries)


def request_state(lab: Lab) -> dict[str, Any]:
    async def get() -> dict[str, Any]:
        async with aiohttp.ClientSession() as s, s.get(lab.console + "api/state") as r:
            return await r.json()  # type: ignore[no-any-return]

    return in_thread(get)


def harm(lab: Lab, since: float) -> dict[str, int]:
    """What a starved lab shows: each Type II link's connections at its tap (a reconnection is a
    link that dropped), and each IXL's links it logged going down since `since` (the lab's time):
    a Type I link in communication error, the CTC link down."""
    status = lab.lab({"cmd": "status"})["status"]
    out = {f"type2 {n}": t["connections"] for n, t in status["taps"].items() if "connections" in t}
    for name in ("ixl18", "ixl20", "ixl22"):
        events = lab.device(name, {"cmd": "events", "last": 2000})["events"]
        out[f"down {name}"] = sum(
            1
            for e in events
            if e["kind"] == "link"
            and ("communication error" in e["text"] or "link down" in e["text"])
            and e["time"] >= since
        )
    return out


async def flood(url: str) -> tuple[Counter[str], list[dict[str, Any]]]:
    """FLOOD route requests on one websocket, as fast as it takes them; every answer's kind
    (a result's reason, or busy) and the busy answers."""
    answers: Counter[str] = Counter()
    busy: list[dict[str, Any]] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url + "ws") as ws:
        done = asyncio.Event()

        async def read() -> None:
            async for msg in ws:
                data = json.loads(msg.data)
                if data["type"] == "busy":
                    busy.append(data)
                    answers["busy"] += 1
                elif data["type"] == "result":
                    answers["accepted" if data["ok"] else str(data["reason"])] += 1
                if sum(answers.values()) == FLOOD:
                    done.set()

        reader = asyncio.create_task(read())
        for i in range(FLOOD):
            station, entry, exit_ = ROUTES[i % len(ROUTES)]
            await ws.send_str(json.dumps({"type": "route_set", "station": station, "id": i,
                                          "entry": entry, "exit": exit_}))  # fmt: skip
        await asyncio.wait_for(done.wait(), 150)
        reader.cancel()
    return answers, busy


def test_a_flood_of_route_requests_is_answered_busy_and_drops_no_link(
    browser_context: Any, lab: Lab
) -> None:
    page = browser_context.new_page()  # an operator's page beside the flood
    page.goto(lab.console)
    page.wait_for_selector("#conn.up")
    mark = lab.lab({"cmd": "status"})["status"]["time"]
    before = harm(lab, mark)
    answers, busy = in_thread(lambda: flood(lab.console))
    after = harm(lab, mark)

    assert sum(answers.values()) == FLOOD  # every request answered: its result, or busy
    assert answers["busy"] > 0, answers
    assert {b["id"] for b in busy} <= set(range(FLOOD))
    assert all(b["text"].startswith("console busy: route set ") for b in busy)
    # no station disconnected while its controls were out, no control unanswered
    lost = {k: v for k, v in answers.items() if "connected" in k or "CONTROL_RESULT" in k}
    assert not lost, answers
    # no link dropped: no Type II reconnection at a tap, no link an IXL logged going down
    reconnected = {k: after[k] - v for k, v in before.items() if after[k] != v and "type2" in k}
    assert not reconnected, reconnected
    assert not {k: v for k, v in after.items() if v and "down" in k}, after
    stations = lab.stations()
    assert all(s["link"] == "up" and s["synced"] for s in stations.values()), stations
    # the operator's page is told, once for the burst, not once a request
    expect(page.locator("#log .entry.busy").first).to_contain_text("answered busy", timeout=20_000)
    assert page.locator("#log .entry.busy").count() <= 5
    page.close()
