"""SPEC §8 Type II figures: one CTC with 50 IXL clients of 1,000 codes each, on loopback.

1. Full resync, goal <= 2 s: from the moment the IXLs are told to connect until the CTC holds every
   station's full state (IDENT + 25 INDICATION parts per station), checked equal to the IXLs'.
   Measured twice: the cold start (TCP connect + IDENT + dump) and REQUEST_ALL to all 50 stations
   on the open links.
2. Sustained indication changes end to end, goal >= 20,000 /s: every IXL keeps changing random
   codes and pushing them with `IxlClient.indicate()` for `--seconds`; the figure is the changes
   the CTC has applied to its indication tables divided by the time from "go" until the last one was
   applied. Afterwards every indication table is checked equal to its IXL's table.

By default the CTC runs in this process and the 50 IXL clients in a second process (one event loop
for all of them), as in the lab where they are separate programs; `--single-process` puts both in
one event loop. Everything goes through real TCP sockets on 127.0.0.1.

Run: python benchmarks/links_type2.py [--stations 50] [--codes 1000] [--seconds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import platform
import random
import sys
import time
from multiprocessing.connection import Connection
from typing import Any

from ktcs_bench.codec.crc import crc_extension_in_use
from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.transport.ixl_client import IxlClient, StateTable
from ktcs_bench.type2 import events as ev

FIRST_STATION = 100
BATCH = 40  # changes per indicate() call by default: one full INDICATION message


def tables(stations: int, codes: int) -> dict[int, StateTable]:
    rnd = random.Random(1)
    return {
        FIRST_STATION + k: StateTable({c: rnd.randrange(8) for c in range(1, codes + 1)})
        for k in range(stations)
    }


class IxlSide:
    """The 50 IXL clients and the change producer (in the child process or in-process)."""

    def __init__(
        self, port: int, stations: int, codes: int, batch: int = BATCH, delay: float = 0.0
    ) -> None:
        self.batch = batch
        self.apps = tables(stations, codes)
        self.codes = codes
        self.clients = [
            IxlClient(
                st,
                "127.0.0.1",
                port,
                app,
                backoff_initial=0.05,
                backoff_max=0.5,
                indication_delay=delay,
            )  # fmt: skip
            for st, app in self.apps.items()
        ]

    def connect(self) -> None:
        for c in self.clients:
            c.start()

    async def produce(self, seconds: float) -> int:
        """Change codes on every IXL for `seconds`; returns the number of changes pushed."""
        loop = asyncio.get_running_loop()
        rnd = random.Random(2)
        end = loop.time() + seconds
        sent = 0
        while loop.time() < end:
            for c in self.clients:
                state = self.apps[c.station].state
                start = rnd.randrange(1, self.codes - self.batch + 2)
                changes = [
                    (code, (state[code] + 1) & 7) for code in range(start, start + self.batch)
                ]
                state.update(changes)
                c.indicate(changes)
                sent += self.batch
            await asyncio.sleep(0)  # let the batches go out
            for c in self.clients:
                await c.drain()  # returns at once unless the socket's send buffer is full
        return sent

    def snapshot(self) -> dict[int, dict[int, int]]:
        return {st: dict(app.state) for st, app in self.apps.items()}

    async def close(self) -> None:
        for c in self.clients:
            await c.close()


def _child(
    port: int, stations: int, codes: int, batch: int, delay: float, pipe: Connection
) -> None:
    async def main() -> None:
        side = IxlSide(port, stations, codes, batch, delay)
        loop = asyncio.get_running_loop()
        while True:
            cmd, arg = await loop.run_in_executor(None, pipe.recv)
            if cmd == "connect":
                side.connect()
            elif cmd == "produce":
                pipe.send(await side.produce(arg))
            elif cmd == "snapshot":
                pipe.send(side.snapshot())
            elif cmd == "close":
                await side.close()
                pipe.send(None)
                return

    asyncio.run(main())


class Remote:
    """Drives an IxlSide in a child process through a pipe."""

    def __init__(self, port: int, stations: int, codes: int, batch: int, delay: float) -> None:
        ctx = mp.get_context("spawn")
        self.pipe, child = ctx.Pipe()
        args = (port, stations, codes, batch, delay, child)
        self.proc = ctx.Process(target=_child, args=args, daemon=True)
        self.proc.start()

    async def call(self, cmd: str, arg: Any = None, reply: bool = True) -> Any:
        self.pipe.send((cmd, arg))
        if not reply:
            return None
        return await asyncio.get_running_loop().run_in_executor(None, self.pipe.recv)

    async def close(self) -> None:
        await self.call("close")
        self.proc.join(5)


async def bench(
    stations: int, codes: int, seconds: float, single: bool, batch: int, delay: float
) -> list[str]:
    applied = 0

    def on_event(station: int | None, e: ev.SessionEvent) -> None:
        nonlocal applied
        if isinstance(e, ev.IndicationsChanged):
            applied += len(e.items)

    out: list[str] = []
    names = [FIRST_STATION + k for k in range(stations)]
    views = IndicationTables(names)
    async with CtcServer(names, views, on_event=on_event) as ctc:
        local = IxlSide(ctc.port, stations, codes, batch, delay) if single else None
        remote = None if single else Remote(ctc.port, stations, codes, batch, delay)
        if remote is not None:
            await remote.call("snapshot")  # the child is up and its tables are built

        async def snapshot() -> dict[int, dict[int, int]]:
            return local.snapshot() if local is not None else await remote.call("snapshot")  # type: ignore[union-attr]

        def synced() -> bool:
            return all(views.stations[s].synced for s in names)

        # 1a. cold start: connect + IDENT + full state
        t0 = time.perf_counter()
        if local is not None:
            local.connect()
        else:
            await remote.call("connect", reply=False)  # type: ignore[union-attr]
        await ctc.wait_until(synced, timeout=60)
        cold = time.perf_counter() - t0
        truth = await snapshot()
        assert all(views.stations[s].state == truth[s] for s in names), "views differ after resync"
        out.append(
            f"full resync, cold start: {stations} IXLs x {codes} codes in {cold:.3f} s "
            f"({stations * codes / cold:,.0f} codes/s; goal <= 2 s: {'PASS' if cold <= 2 else 'FAIL'})"
        )

        # 1b. REQUEST_ALL to every station on the open links
        before = {s: views.stations[s].full_states for s in names}
        t0 = time.perf_counter()
        for s in names:
            ctc.request_all(s)
        await ctc.wait_until(
            lambda: all(views.stations[s].full_states > before[s] for s in names), timeout=60
        )
        warm = time.perf_counter() - t0
        out.append(
            f"full resync, REQUEST_ALL on open links: {stations} x {codes} codes in {warm:.3f} s "
            f"(goal <= 2 s: {'PASS' if warm <= 2 else 'FAIL'})"
        )

        # 2. sustained change indications, end to end
        applied = 0
        t0 = time.perf_counter()
        if local is not None:
            sent = await local.produce(seconds)
        else:
            sent = await remote.call("produce", seconds)  # type: ignore[union-attr]
        await ctc.wait_until(lambda: applied >= sent, timeout=120)
        elapsed = time.perf_counter() - t0
        rate = applied / elapsed
        truth = await snapshot()
        same = all(views.stations[s].state == truth[s] for s in names)
        out.append(
            f"sustained indications: {applied:,} changes in {elapsed:.2f} s = {rate:,.0f} changes/s "
            f"end to end ({batch} per indicate() call, indication_delay {delay * 1000:g} ms; goal >= 20,000/s: {'PASS' if rate >= 20000 else 'FAIL'}); "
            f"CTC views equal to IXL tables afterwards: {same}"
        )
        if local is not None:
            await local.close()
        else:
            await remote.close()  # type: ignore[union-attr]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--stations", type=int, default=50)
    ap.add_argument("--codes", type=int, default=1000)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--single-process", action="store_true")
    ap.add_argument("--batch", type=int, default=BATCH, help="changes per indicate() call")
    ap.add_argument("--delay", type=float, default=0.0, help="IxlClient indication_delay, s")
    args = ap.parse_args()
    mode = "CTC and IXLs in one event loop" if args.single_process else "CTC | IXLs in 2 processes"
    print(f"Type II links benchmark -- Python {platform.python_version()}, {platform.machine()}, "
          f"{mp.cpu_count()} CPUs, crcmod C extension: {crc_extension_in_use()}, {mode}")  # fmt: skip
    lines = asyncio.run(
        bench(args.stations, args.codes, args.seconds, args.single_process, args.batch, args.delay)
    )
    for line in lines:
        print(line)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
