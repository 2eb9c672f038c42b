"""`ktcs-bench tap`: run a tap between two ends of a link, and command a running one."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping
from typing import TypedDict

from ktcs_bench.capture import CaptureWriter, open_writer
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.errors import UsageError
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.control import HELP as CONTROL_HELP
from ktcs_bench.tap.control import parse_command
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.registry import known_taps, parse_tap_address
from ktcs_bench.tap.runner import Tap
from ktcs_bench.tap.tcp import TcpTap

HELP = "run a recording, fault-injecting tap on a link; command a running tap"
DESCRIPTION = """\
A tap sits between the two ends of a link, records both directions with timestamps, serves them to
monitors, and injects faults on command.
  --pty              create two pty pairs; end A opens the first path, end B the second
  --tcp LISTEN TARGET  listen on LISTEN; each connection is forwarded to TARGET
The tap prints its pty paths / addresses and its control port; `tap fault` sends it commands
(the words below, sent as the JSON lines every control port of the bench speaks).
"""
EPILOG = (
    """\
examples:
  ktcs-bench tap run --pty --names ixl,atc --name st18-ixl-atc --write st18.hex
  ktcs-bench tap run --tcp 127.0.0.1:6020 127.0.0.1:5020 --names ixl,ctc --write t2.pcapng
  ktcs-bench tap fault st18-ixl-atc ber 1e-3
  ktcs-bench tap fault 127.0.0.1:40111 drop-frame 'ixl->atc'
  ktcs-bench tap fault st18-ixl-atc garbage 'ixl->atc' 02 ff 00
  ktcs-bench tap fault st18-ixl-atc cut        # ... later: restore, clear
  ktcs-bench tap status st18-ixl-atc
  ktcs-bench monitor st18-ixl-atc

control commands (TAP is a name given with --name, HOST:PORT of the control port, or PORT):
"""
    + CONTROL_HELP
)


def _address(text: str, what: str, any_free: bool = False) -> tuple[str, int]:
    addr = parse_tap_address(
        text.removeprefix("tcp://").removeprefix("listen://"), what, any_free=any_free
    )
    if addr is None:
        raise UsageError(f"{what} must be HOST:PORT or PORT, not {text!r}")
    return addr


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "tap", help=HELP, description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    tsub = p.add_subparsers(dest="tap_command", metavar="ACTION")
    run_p = tsub.add_parser(
        "run", help="run a tap (until Ctrl-C / SIGTERM)", description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    kind = run_p.add_mutually_exclusive_group(required=True)
    kind.add_argument("--pty", action="store_true", help="between two new pty pairs (Type I)")
    kind.add_argument("--tcp", nargs=2, metavar=("LISTEN", "TARGET"), help="between TCP ends")
    run_p.add_argument("--names", default="a,b", help="names of end A and end B (default a,b)")
    run_p.add_argument(
        "--profile", help="frame profile (default ktcs-type1 for --pty, ktcs-type2 for --tcp)"
    )
    run_p.add_argument("--name", help="announce the tap under this name (for fault/monitor)")
    run_p.add_argument(
        "--control", default="127.0.0.1:0", metavar="[HOST:]PORT",
        help="control port address (default 127.0.0.1, any free port)",
    )  # fmt: skip
    run_p.add_argument(
        "--token-file", metavar="FILE",
        help="the token its control port requires, kept in FILE (mode 0600; made if missing); "
        "default: $KTCS_BENCH_TOKEN_FILE, else the user's token in the run folder",
    )  # fmt: skip
    run_p.add_argument("--seed", type=int, default=0, help="seed of the fault RNG (default 0)")
    run_p.add_argument(
        "--write", action="append", default=[], metavar="FILE",
        help="record to FILE.hex (hex log) or FILE.pcapng (repeatable)",
    )  # fmt: skip
    run_p.add_argument(
        "--fault", action="append", default=[], metavar="COMMAND",
        help="a control command to apply at start, e.g. --fault 'ber 1e-4' (repeatable)",
    )  # fmt: skip
    run_p.add_argument("--json", action="store_true", help="print the tap's info as one JSON line")
    run_p.set_defaults(handler=run_tap)

    fault_p = tsub.add_parser(
        "fault", help="send a control command to a running tap", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    fault_p.add_argument("tap", metavar="TAP", help="tap name, HOST:PORT or PORT")
    fault_p.add_argument("words", nargs="+", metavar="COMMAND", help="e.g. ber 1e-3")
    fault_p.set_defaults(handler=run_fault)

    status_p = tsub.add_parser("status", help="a running tap's ends, faults and counters")
    status_p.add_argument("tap", metavar="TAP")
    status_p.set_defaults(handler=run_status)

    list_p = tsub.add_parser("list", help="the named taps running on this machine")
    list_p.set_defaults(handler=run_list)
    p.set_defaults(handler=lambda args: (p.print_help(), 2)[1])


def _names(text: str) -> tuple[str, str]:
    parts = [x.strip() for x in text.split(",")]
    if len(parts) != 2 or not all(parts):
        raise UsageError(f"--names takes two names separated by a comma, not {text!r}")
    return parts[0], parts[1]


class _TapOptions(TypedDict):
    """What `tap run` gives a tap of either kind."""

    names: tuple[str, str]
    seed: int
    control: tuple[str, int]
    name: str | None
    token_file: str | None
    profile: FrameProfile
    writers: list[CaptureWriter]


def _print_info(tap: Tap, as_json: bool) -> None:
    info = tap.info()
    if as_json:
        print(json.dumps(info), flush=True)
        return
    assert info["control"] is not None  # `tap run` always opens its control port
    host, port = info["control"]
    title = f"tap {info['name']}" if info["name"] else "tap"
    lines = [f"{title} ({info['kind']}, profile {info['profile']}); control {host}:{port}"]
    a, b = info["names"]
    if "paths" in info:
        lines += [f"  end {end}: open {path}" for end, path in info["paths"].items()]
    else:
        lines.append(f"  end {a}: connect to {info['listen'][0]}:{info['listen'][1]}")
        lines.append(f"  end {b}: the tap connects to {info['target'][0]}:{info['target'][1]}")
    lines.append(f"  faults: ktcs-bench tap fault {info['name'] or port} COMMAND   (Ctrl-C stops)")
    print("\n".join(lines), flush=True)


def run_tap(args: argparse.Namespace) -> int:
    names = _names(args.names)
    faults = [parse_command(command, names) for command in args.fault]  # refused before the start
    control = _address(args.control, "--control", any_free=True)
    profile = get_profile(args.profile or ("ktcs-type1" if args.pty else "ktcs-type2"))
    common: _TapOptions = {
        "names": names, "seed": args.seed, "control": control, "name": args.name,
        "token_file": args.token_file, "profile": profile,
        "writers": [open_writer(path, link=profile.protocol, profile=profile.name)
                    for path in args.write],
    }  # fmt: skip
    tap: Tap
    if args.pty:
        tap = PtyTap(**common)
    else:
        tap = TcpTap(
            _address(args.tcp[0], "LISTEN", any_free=True),
            _address(args.tcp[1], "TARGET"),
            **common,
        )

    def ready(t: Tap) -> None:
        for cmd in faults:
            answer = t.execute(cmd.to_json())
            if not answer.get("ok"):
                print(f"ktcs-bench: tap: {cmd.words()}: {answer.get('error')}", file=sys.stderr)
        _print_info(t, args.json)

    tap.run(ready)
    return 0


def run_fault(args: argparse.Namespace) -> int:
    with TapClient(args.tap) as client:
        print(client.command(" ".join(args.words)))
    return 0


def run_status(args: argparse.Namespace) -> int:
    with TapClient(args.tap) as client:
        print(json.dumps(client.status(), indent=1))
    return 0


def run_list(args: argparse.Namespace) -> int:
    for info in known_taps():
        host, port = info.get("control") or ("?", "?")
        ends: Mapping[str, object] = info.get("paths") or {
            "listen": info.get("listen"),
            "target": info.get("target"),
        }
        print(f"{info.get('name')}  {info.get('kind')}  control {host}:{port}  {json.dumps(ends)}")
    return 0
