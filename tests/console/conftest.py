"""A running bench for the console tests: a real CtcServer, three real interlockings (IXL +
trackside, `console.demo.RigIxl`) as Type II clients over TCP on 127.0.0.1 (station 18 through a
real TCP tap), two ConsoleServers, and headless Chromium (Debian's) driven by Playwright.

The asyncio side runs in a thread of its own; tests call into it with `bench.call(coro)`.
"""

from __future__ import annotations

import asyncio
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any, TypeVar

import pytest

from ktcs_bench.console.demo import RigIxl, with_throw_time
from ktcs_bench.console.server import ConsoleServer
from ktcs_bench.ctc.desk import Desk
from ktcs_bench.ctc.model import CtcModel
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.station.loader import load_line
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import CycleInputs, LineData, TrainConfig, TrainEndpoint
from ktcs_bench.train.mrsp import Restriction
from ktcs_bench.train.units import kmh
from ktcs_bench.transport.ctc_server import CtcServer

T = TypeVar("T")
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip
THROW_S = 2.0  # point throw time in these tests (the reference data says 4 s)
ARTIFACTS = Path(__file__).resolve().parents[2] / "out" / "console"  # /out/ is git-ignored


def make_train() -> TrainEndpoint:
    line = LineData(
        length=3000.0,
        tags=[i * 100.0 for i in range(31)],
        restrictions=[Restriction(0.0, 1500.0, kmh(80.0)), Restriction(1500.0, 3000.0, kmh(40.0))],
    )
    ep = TrainEndpoint(TrainConfig("T1", TrainParams(), start=500.0), line)
    for i in range(100):
        ep.step(i * 0.1, CycleInputs(authority_end=2500.0))
    return ep


class Bench:
    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.line = with_throw_time(load_line(), THROW_S)
        self.train = make_train()
        self.rigs: dict[int, RigIxl] = {}
        self.tap: TcpTap | None = None

    def call(self, coro: Awaitable[T], timeout: float = 20.0) -> T:
        fut: Future[T] = asyncio.run_coroutine_threadsafe(coro, self.loop)  # type: ignore[arg-type]
        return fut.result(timeout)

    def do(self, fn: Callable[[], T]) -> T:
        async def run() -> T:
            return fn()

        return self.call(run())

    async def start(self) -> None:
        self.model = CtcModel(self.line)
        self.ctc = CtcServer(sorted(self.line.stations), self.model.tables)
        desk = Desk(self.model, self.ctc, clock=time.time)
        await self.ctc.start()
        self.tap = TcpTap(("127.0.0.1", 0), ("127.0.0.1", self.ctc.port), names=("ixl", "ctc"))
        await asyncio.to_thread(self.tap.start)
        assert self.tap.listen_address is not None and self.tap.control_address is not None
        host, port = self.tap.control_address
        self.console = ConsoleServer(desk, taps=[f"{host}:{port}"], trains={"T1": self.train})
        await self.console.start()
        self.bare = ConsoleServer(desk)  # no taps, no trains
        await self.bare.start()
        for n in sorted(self.line.stations):
            self.start_rig(n, Mode.LOCAL if n == 22 else Mode.CENTER)
        await self.ctc.wait_until(
            lambda: all(v.connected and v.synced for v in self.model.tables.stations.values()), 10.0
        )

    def start_rig(self, n: int, mode: Mode) -> RigIxl:
        rig = RigIxl(self.line, n, mode=mode)
        if n == 18:
            assert self.tap is not None and self.tap.listen_address is not None
            rig.start(*self.tap.listen_address)
        else:
            rig.start("127.0.0.1", self.ctc.port)
        self.rigs[n] = rig
        return rig

    async def stop(self) -> None:
        for rig in self.rigs.values():
            await rig.close()
        await self.bare.close()
        await self.console.close()
        await self.ctc.close()
        if self.tap is not None:
            await asyncio.to_thread(self.tap.stop)

    def close(self) -> None:
        try:
            self.call(self.stop())
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(5)
            self.loop.close()


@pytest.fixture(scope="module")
def bench() -> Iterator[Bench]:
    b = Bench()
    try:
        b.call(b.start())
        yield b
    finally:
        b.close()


@pytest.fixture(scope="module")
def browser_context() -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="ktcs-console-chromium-") as profile:
        with sync_playwright() as p:
            ctx = p.chromium.launch_persistent_context(
                profile,
                executable_path=CHROMIUM,
                args=CHROMIUM_ARGS,
                viewport={"width": 2100, "height": 1000},
            )
            ctx.set_default_timeout(10_000)
            try:
                yield ctx
            finally:
                ctx.close()


@pytest.fixture
def page(browser_context: Any, bench: Bench) -> Iterator[Any]:
    pg = browser_context.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda exc: errors.append(str(exc)))
    pg.goto(bench.console.url)
    pg.wait_for_selector("#conn.up")
    pg.wait_for_selector("#diagram")
    yield pg
    pg.close()
    assert not errors, f"JavaScript errors on the page: {errors}"
