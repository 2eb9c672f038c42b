"""`ktcs-bench console`: a standalone CTC (Type II server) with its operator console web page."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import time
from pathlib import Path

from ktcs_bench.cli._common import duration, port

HELP = "run a CTC with its web operator console (route setting, link monitor, speed-distance)"
EPILOG = """\
examples:
  ktcs-bench console --ctc-port 5020 --port 8020          # then start the IXLs against :5020
  ktcs-bench console --demo-ixls                          # with in-process interlockings
  ktcs-bench console --tap st18-ctc --tap 127.0.0.1:7001  # link monitor over these taps
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "console",
        help=HELP,
        description="Start a CTC Type II server and its operator console (a web page). The "
        "console prints its URL; open it in a browser. IXLs connect to the CTC port.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--host", default="127.0.0.1", help="address of both servers (127.0.0.1)")
    p.add_argument(
        "--port", type=port(any_free=True), default=0, help="console HTTP port (0: any free port)"
    )
    p.add_argument(
        "--ctc-port", type=port(any_free=True), default=0, help="Type II port (0: any free port)"
    )
    p.add_argument("--line", type=Path, help="line file (default: the reference line)")
    p.add_argument("--tap", action="append", default=[], help="tap name or HOST:PORT (repeat)")
    p.add_argument(
        "--demo-ixls", action="store_true", help="run each station's IXL + trackside in-process"
    )
    p.add_argument("--throw-time", type=duration, help="point throw time for --demo-ixls, s")
    p.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(_serve(args))
    return 0


async def _serve(args: argparse.Namespace) -> None:
    # imported here so that other subcommands do not pay for aiohttp
    from ktcs_bench.console.demo import RigIxl, with_throw_time
    from ktcs_bench.console.server import ConsoleServer
    from ktcs_bench.ctc.desk import Desk
    from ktcs_bench.ctc.model import CtcModel
    from ktcs_bench.station.loader import load_line
    from ktcs_bench.transport.ctc_server import CtcServer

    line = load_line(args.line)
    if args.throw_time is not None:
        line = with_throw_time(line, args.throw_time)
    model = CtcModel(line)
    ctc = CtcServer(sorted(line.stations), model.tables, host=args.host, port=args.ctc_port)
    await ctc.start()
    console = ConsoleServer(
        Desk(model, ctc, clock=time.time), taps=args.tap, host=args.host, port=args.port
    )
    await console.start()
    rigs = []
    if args.demo_ixls:
        for n in sorted(line.stations):
            rig = RigIxl(line, n)
            rig.start(args.host, ctc.port)
            rigs.append(rig)
    print(f"CTC Type II server on {args.host}:{ctc.port}", flush=True)
    print(f"console: {console.url}", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await stop.wait()
    finally:
        for rig in rigs:
            await rig.close()
        await console.close()
        await ctc.close()
