"""`ktcs-bench ctc`: the CTC operator console in a terminal -- route set/cancel, points, signals,
center/local requests, station views -- talking to a running CTC's control port."""

from __future__ import annotations

import argparse
import asyncio
import json
import shlex
import time
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.cli._common import host_port
from ktcs_bench.ctc.log import parse_words
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.messages import Ars, Log, Show, Status
from ktcs_bench.transport import jsonlines

HELP_TEXT = """\
commands:
  route set ST ENTRY EXIT        e.g. route set 20 S1 S11   (signals as S1, S01 or 01)
  route cancel ST ENTRY EXIT
  point normal|reverse ST POINT  e.g. point reverse 20 31
  signal stop|release ST SIGNAL
  mode center|local ST           center: request center mode (CMR handshake)
  direction ST INTERVAL          ask the neighbour for the interval's traffic permission
                                 ahead of a departure route, e.g. direction 20 1820
  control ST CODE [VALUE]        any CTC->IXL chart code by name
  show ST                        mode, routes, points, signals, occupancy, link, and each
                                 interval's direction and holder
  ars [on|off] [ST]              automatic route setting: switch it at ST (no ST: every
                                 station); without on/off, where it is on and what each train
                                 waits for
  status                         every station
  log                            the CTC's command log
  help, quit
"""
EPILOG = """\
examples:
  ktcs-bench ctc                                  # interactive, against the running reference lab
  ktcs-bench ctc route set 18 01 11               # one command
  ktcs-bench ctc direction 20 1820                # station 20 asks 18 for interval 1820
  ktcs-bench ctc ars off 20                       # routes at station 20 by hand from now on
  ktcs-bench ctc --script morning.txt --json      # scripted controls, JSON results
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "ctc", help="the CTC operator console (route set, points, modes, station views)",
        description="Operate a running CTC: every command goes to the IXL as a CONTROL and its "
        "CONTROL_RESULT (accepted, or rejected with the reason) comes back. " + HELP_TEXT,
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    p.add_argument("command", nargs="*", help="one command (else: interactive, or --script)")
    p.add_argument("--lab", default="reference", help="the running lab whose CTC to use")
    p.add_argument(
        "--address", type=host_port(), help="HOST:PORT of a CTC control port (instead of --lab)"
    )
    p.add_argument("--script", help="a file of commands, one a line (# comments)")
    p.add_argument("--json", action="store_true", help="results as JSON lines")
    p.set_defaults(handler=run)


def _address(args: argparse.Namespace) -> tuple[str, int]:
    if args.address:
        return args.address  # type: ignore[no-any-return]
    from ktcs_bench.lab.state import attach

    state = attach(args.lab)
    ctc = next((d for d in state["devices"].values() if d.get("kind") == kinds.CTC), None)
    if ctc is None:
        raise UsageError(f"lab {args.lab} has no CTC")
    host, _, port = ctc["control"].rpartition(":")
    return host, int(port)


def show_text(answer: dict[str, Any]) -> str:
    """One station as the CTC sees it; what it does not know (link down, no full state yet) reads
    "unknown", never the last indications."""
    s = answer["summary"]
    known = s.get("known", True)
    none = "-" if known else "unknown"
    lines = [f"station {s['station']}: {s['mode']} mode, link {s['link']}"
             + (" (center requested)" if s.get("center_requested") else "")
             + ("" if known else " (indications unknown until the IXL sends its full state)")]  # fmt: skip
    lines.append("  routes   " + (", ".join(s["routes"]) or none))
    lines.append("  points   " + " ".join(f"{k}:{v}" for k, v in s["points"].items()))
    lines.append("  signals  " + " ".join(f"{k}:{v}" for k, v in s["signals"].items()))
    lines.append("  occupied " + (" ".join(s["occupied"]) or none))
    for iv in s.get("intervals", {}).values():
        lines.append("  interval " + iv["text"])
    return "\n".join(lines)


def ars_text(answer: dict[str, Any]) -> str:
    """ARS as the operator reads it: where it is on, each train and what it waits for."""
    a = answer["ars"]
    on = ", ".join(f"{st} {'on' if v else 'off'}" for st, v in a["stations"].items())
    lines = [f"ARS (timetable {a['timetable']}): station {on}"]
    for t in a["trains"]:
        text = f"  train {t[kinds.TRAIN]}: {t['state']}"
        if t.get("next"):
            text += f"; next {t['next']}"
        if t.get("waiting"):
            text += f"; waits: {t['waiting']}"
        lines.append(text)
    return "\n".join(lines)


async def _session(args: argparse.Namespace, commands: list[list[str]] | None) -> int:
    host, port = _address(args)
    colour: bool = args.colour
    failed = False

    async def one(words: list[str]) -> None:
        nonlocal failed
        if words and words[0].lower() == "help":
            print(HELP_TEXT)
            return
        message = parse_words(words)
        try:
            answer = await jsonlines.request(host, port, message, timeout=30)
        except OSError as exc:
            raise PeerError(f"the CTC at {host}:{port} does not answer: {exc}") from None
        stamp = time.strftime("%H:%M:%S")
        if args.json:
            print(
                json.dumps({"time": time.time(), "command": " ".join(words), **answer}), flush=True
            )
        elif isinstance(message, Show) and answer.get("ok"):
            print(show_text(answer))
        elif isinstance(message, Status) and answer.get("ok"):
            for st in answer["status"].get("stations", {}).values():
                print(show_text({"summary": st}))
        elif isinstance(message, Ars) and answer.get("ok"):
            print(ars_text(answer))
        elif isinstance(message, Log):
            for e in answer.get("log", []):
                at = time.strftime("%H:%M:%S", time.localtime(e["time"]))
                by = f" (by {e['source'].upper()})" if e.get("source") == "ars" else ""
                print(f"{at} {e['command']}{by} -> {e.get('result', 'no result yet')}")
        else:
            text = (
                answer.get("result")
                or answer.get("error")
                or ("ok" if answer.get("ok") else "failed")
            )
            ok = bool(answer.get("ok"))
            mark = ("\x1b[32m" if ok else "\x1b[31m") if colour else ""
            reset = "\x1b[0m" if colour else ""
            print(
                f"{stamp} {' '.join(words)} -> {mark}{text}{reset}",
                flush=True,
            )
        if not isinstance(message, Show | Status | Log) and not answer.get("ok"):
            failed = True

    if commands is not None:
        for words in commands:
            await one(words)
        return 1 if failed else 0
    print(f"CTC at {host}:{port}. Type `help` for commands, `quit` to leave.")
    while True:
        try:
            line = await asyncio.to_thread(input, "ctc> ")
        except EOFError:
            return 0
        words = shlex.split(line)
        if not words:
            continue
        if words[0].lower() in ("quit", "exit"):
            return 0
        try:
            await one(words)
        except UsageError as exc:
            print(f"error: {exc}")


def run(args: argparse.Namespace) -> int:
    commands: list[list[str]] | None = None
    if args.script:
        try:
            text = open(args.script, encoding="utf-8").read()
        except OSError as exc:
            raise UsageError(f"cannot read {args.script}: {exc.strerror}") from None
        commands = [shlex.split(ln.split("#", 1)[0]) for ln in text.splitlines()]
        commands = [c for c in commands if c]
    elif args.command:
        commands = [args.command]
    return asyncio.run(_session(args, commands))
