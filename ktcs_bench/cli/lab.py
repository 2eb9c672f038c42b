"""`ktcs-bench lab up|down|restart|status|kill|simulate`: the whole lab as processes on ptys and
TCP, or in this process on a virtual (`simulate`) or scaled (`up --in-process`) clock."""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
from functools import partial
from typing import TYPE_CHECKING, Any

from ktcs_bench import kinds
from ktcs_bench.cli._common import duration, positive
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.lab.runner import GROUPINGS
from ktcs_bench.lab.topology import load_lab, resolve_lab_path
from ktcs_bench.timed.vloop import MAX_SPEED
from ktcs_bench.transport import jsonlines

if TYPE_CHECKING:
    from ktcs_bench.lab.invariants import Violation

SIMULATE_EXITS = """\
`lab simulate` runs the lab invariants throughout (SPEC §11: no two trains in one track circuit,
no train past a danger point, no point moving under a train or a locked route, no point trailed,
no derailment): each violation is one line on stderr as it is found and one entry of
`violations` in summary.json. Exit 0: the run ended and broke no invariant; 1: it ran and found
violations; 2: usage; 3: a device crashed or the lab stalled; 130/143: interrupted.
"""

EPILOG = f"""\
examples:
  ktcs-bench lab up                      # the shipped reference lab (stations 18, 20, 22)
  ktcs-bench lab up my-lab.yaml --for 60 # a lab of your own, stop after 60 s
  ktcs-bench lab status --json           # from another shell: the live state as JSON
  ktcs-bench lab restart ixl20           # bring a crashed device back (full resync follows)
  ktcs-bench lab down
  ktcs-bench lab simulate --for 3600 --seed 1 --out run1   # an hour of the lab in virtual time
  ktcs-bench lab up --in-process --speed 10                # one process, 10x real time, console
  ktcs-bench lab up spread.yaml --host west --token-file lab.token  # this computer's part of a
                                         # lab spread over hosts (`hosts:`; docs/multihost.md)
  ktcs-bench lab down --all              # every host's part of a spread lab

Ctrl-C (or SIGTERM) stops `lab up` and `lab simulate`: exit 130 (143 on SIGTERM); a simulation
writes its events, captures and summary up to that moment. `lab down`, or `--for` running out,
ends `lab up` with exit 0. A shared device's labgrid place (`external: {{labgrid: PLACE}}`) held by
someone else, or a coordinator that does not answer, ends `lab up` with exit 3 naming the holder
or the coordinator (`--wait-for-place` waits instead); the place is released however `lab up`
ends.

{SIMULATE_EXITS}"""


def _speed(text: str) -> float:
    """The argparse type of `--speed`: a positive number up to `MAX_SPEED`."""
    value: float = positive(float, 0.001)(text)
    if value > MAX_SPEED:
        raise argparse.ArgumentTypeError(
            f"at most {MAX_SPEED:g} (times real time), not {text!r}: above that a lab in one "
            "process cannot keep its links up"
        )
    return value


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "lab", help="start, watch and stop a whole lab (every device its own process)",
        description="Run a lab from a topology file: every device is its own process, Type I "
        "links are paced ptys through taps, Type II links TCP through taps.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    lsub = p.add_subparsers(dest="lab_command", metavar="ACTION", required=True)
    up = lsub.add_parser("up", help="start the lab and show its live status (Ctrl-C stops it)")
    up.add_argument("lab", nargs="?", help="lab file or shipped lab name (default: reference)")
    up.add_argument("--for", dest="duration", type=duration, help="stop after this many seconds")
    up.add_argument("--unpaced", action="store_true", help="Type I without line-rate pacing")
    up.add_argument(
        "--json", action="store_true", help="print the link map and status as JSON lines"
    )
    up.add_argument("--interval", type=duration, default=1.0, help="status refresh period (s)")
    up.add_argument(
        "--in-process", action="store_true",
        help="every device in this one process on a scaled clock (the light way on a small "
        "machine), with the web console and control ports on real sockets",
    )  # fmt: skip
    up.add_argument(
        "--group", choices=GROUPINGS, default="none",
        help="devices per process: none (default: every device its own process, the most "
        "faithful) or station (a station's IXL, ATC and trackside in one process, their Type I "
        "links still over the taps' ptys: less memory, a faster start)",
    )  # fmt: skip
    up.add_argument("--wait-for-place", action="store_true",
                    help="a labgrid place (external: {labgrid: PLACE}) someone else holds: wait "
                    "until it is released (default: exit 3 naming the holder); Ctrl-C gives up")  # fmt: skip
    up.add_argument("--place-timeout", type=duration, metavar="SECONDS",
                    help="with --wait-for-place: give up after this long (exit 3)")  # fmt: skip
    up.add_argument("--host", metavar="NAME",
                    help="run only the devices the lab file places on host NAME (`hosts:`), "
                    "linked to the other hosts' over TCP and RFC 2217 (docs/multihost.md)")  # fmt: skip
    up.add_argument("--token-file", metavar="FILE",
                    help="with --host: the lab's token, the same file copied to every host "
                    "(made here if missing; default: hosts.NAME.token_file, $KTCS_BENCH_TOKEN_FILE)")  # fmt: skip
    up.add_argument("--speed", type=_speed, default=None,
                    help=f"with --in-process: the clock's speed, times real time (default 1, at "
                    f"most {MAX_SPEED:g}; a warning says when this machine does not keep up)")  # fmt: skip
    sim = lsub.add_parser(
        "simulate", help="run the whole lab in this process on a virtual clock, as fast as it goes",
        description="Run every device of the lab in this process on a virtual clock that jumps "
        "from deadline to deadline: the same device objects, Type I links paced at the line rate "
        "on virtual wires, Type II on memory streams, the taps between. Writes OUT/events.jsonl "
        "(every device's events, virtual timestamps), OUT/captures/LINK.pcapng and "
        "OUT/summary.json. Same lab, seed and duration: byte-identical events and captures. "
        "The lab invariants are checked throughout: each violation is printed on stderr as it "
        "is found and listed in the summary (`violations`); exit 1 when there were any.",
        epilog=SIMULATE_EXITS, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    sim.add_argument("lab", nargs="?", help="lab file or shipped lab name (default: reference)")
    sim.add_argument("--for", dest="duration", type=duration,
                     help="seconds of virtual time to run (not with --replay)")  # fmt: skip
    sim.add_argument("--seed", type=int, default=0, help="seed of the taps' fault injectors")
    sim.add_argument("--out", help="folder for events, captures and summary (optional with "
                     "--replay)")  # fmt: skip
    sim.add_argument("--replay", metavar="FILE",
                     help="run a safety-search failure again (docs/system_safety.md): the file's "
                     "lab, seed and steps, with the search's checks and the lab invariants "
                     "throughout; exit 1 on a violation")  # fmt: skip
    sim.add_argument("--json", action="store_true", help="print the summary as JSON")
    for name, text in (("down", "stop a running lab"), ("status", "show a running lab's status"),
                       ("map", "show a running lab's link map")):  # fmt: skip
        q = lsub.add_parser(name, help=text)
        q.add_argument("lab", nargs="?", help="lab name (default: reference)")
        q.add_argument("--json", action="store_true")
        if name == "down":
            q.add_argument("--all", action="store_true",
                           help="a lab spread over hosts: stop every host's part, not only this one's")  # fmt: skip
    for name, text in (("restart", "restart one device (a full resync follows)"),
                       ("kill", "kill one device with SIGKILL, as a crash would")):  # fmt: skip
        q = lsub.add_parser(name, help=text)
        q.add_argument("device")
        q.add_argument("--lab", help="lab name (default: reference)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    if args.lab_command == "up":
        if args.speed is not None and not args.in_process:
            raise UsageError("lab up: --speed sets the clock of a lab in one process: give "
                             "--in-process too (a lab of processes runs on the wall clock)")  # fmt: skip
        if args.place_timeout is not None and not args.wait_for_place:
            raise UsageError("lab up: --place-timeout is how long --wait-for-place waits: give "
                             "--wait-for-place too")  # fmt: skip
        if args.in_process and args.host is not None:
            raise UsageError("lab up: --host runs a host's part of a lab as processes; "
                             "not with --in-process")  # fmt: skip
        return _up_in_process(args) if args.in_process else _up(args)
    if args.lab_command == "simulate":
        return _simulate(args)
    lab_name = getattr(args, "lab", None) or "reference"
    lab_name = load_lab(resolve_lab_path(lab_name)).name if lab_name.endswith(".yaml") else lab_name
    if args.lab_command == "down":
        return _down(lab_name, everywhere=args.all)
    if args.lab_command in ("restart", "kill"):
        answer = _request(lab_name, {"cmd": args.lab_command, "device": args.device})
        if not answer.get("ok"):
            raise UsageError(str(answer.get("error")))
        print(f"{args.device}: {'restarted' if args.lab_command == 'restart' else 'killed'}")
        return 0
    if args.lab_command == "map":
        links = _request(lab_name, {"cmd": "map"})["links"]
        if args.json:
            print(json.dumps(links))
        else:
            from ktcs_bench.lab.view import link_map_text

            print(link_map_text(links, args.colour))
        return 0
    status = _request(lab_name, {"cmd": "status"})["status"]
    if args.json:
        print(json.dumps(status))
    else:
        from ktcs_bench.lab.multihost import host_lines
        from ktcs_bench.lab.view import station_lines

        lines = [*station_lines(status, args.colour), *process_lines(status), *host_lines(status)]
        print("\n".join(lines))
    return 0


def process_lines(status: dict[str, Any]) -> list[str]:
    """The processes of a lab whose devices share them (`lab up --group station`), each with its
    devices; nothing when every device has a process of its own."""
    processes: dict[str, tuple[object, list[str]]] = {}
    for name, entry in (status.get("devices") or {}).items():
        process = entry.get("process") if isinstance(entry, dict) else None
        if isinstance(process, dict):
            key = str(process.get("name"))
            processes.setdefault(key, (process.get("pid"), []))[1].append(name)
    if all(len(names) < 2 for _, names in processes.values()):
        return []
    return ["processes:"] + [
        f"  {key} (pid {pid}): {' '.join(names)}" for key, (pid, names) in processes.items()
    ]


def _request(lab_name: str, obj: dict[str, Any]) -> dict[str, Any]:
    from ktcs_bench.lab.state import attach

    host, _, port = str(attach(lab_name)["control"]).rpartition(":")
    if not port:
        raise PeerError(f"lab {lab_name} is still starting; try again when `lab up` says it is up")
    try:
        return asyncio.run(jsonlines.request(host, int(port), obj, timeout=30))
    except (OSError, TimeoutError) as exc:
        raise PeerError(f"lab {lab_name} does not answer on {host}:{port}: {exc}") from None


def _down(lab_name: str, everywhere: bool = False) -> int:
    """Stop a running lab and wait until it has stopped; clean up after one that died.
    `everywhere`: a lab spread over hosts asks every host's part to stop too."""
    from ktcs_bench.lab.processes import wait_for
    from ktcs_bench.lab.state import clean_up_after, is_alive, read_state
    from ktcs_bench.runtime import process_alive

    state = read_state(lab_name)
    if state is not None and not is_alive(state):
        for line in clean_up_after(lab_name):
            print(line)
        return 0
    answer = _request(lab_name, {"cmd": "down", **({"all": True} if everywhere else {})})
    for host, what in (answer.get("hosts") or {}).items():
        print(f"lab {lab_name} on host {host}: {what}", flush=True)
    assert state is not None
    pid, started = int(state["pid"]), state.get("started")
    print(f"lab {lab_name}: stopping", flush=True)
    if not wait_for(lambda: not process_alive(pid, started), 60.0, 0.1):
        raise PeerError(f"lab {lab_name} (pid {pid}) has not stopped within 60 s")
    print(f"lab {lab_name}: stopped")
    return 0


def _up(args: argparse.Namespace) -> int:
    import logging

    from ktcs_bench.lab.multihost import host_lines
    from ktcs_bench.lab.runner import LabRunner
    from ktcs_bench.lab.view import RED, RESET, link_map_text, station_lines

    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    lab = load_lab(resolve_lab_path(args.lab))
    colour = args.colour
    runner: LabRunner
    if args.host is not None:
        from ktcs_bench.lab.multihost import host_runner

        runner = host_runner(
            lab, args.host, args.token_file, unpaced=args.unpaced, group=args.group
        )
    elif lab.hosts:
        raise UsageError(f"lab {lab.name} is spread over hosts ({', '.join(lab.hosts)}): start "
                         "each host's part there with `ktcs-bench lab up LAB --host NAME`")  # fmt: skip
    elif args.token_file is not None:
        raise UsageError("lab up: --token-file goes with --host (a lab on one machine keeps its "
                         "token in its run folder)")  # fmt: skip
    else:
        runner = LabRunner(lab, unpaced=args.unpaced, group=args.group)
    if args.wait_for_place:
        runner.wait_for_place = math.inf if args.place_timeout is None else args.place_timeout

    stopped_by: list[int] = []  # the signal that stopped it (exit 128 + it), if one did

    def on_signal(sig: int) -> None:
        stopped_by.append(sig)
        runner.stop_requested.set()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, on_signal, sig)
        try:
            if not args.json:
                print(
                    f"lab {lab.name}: starting {len(lab.devices)} devices, {len(lab.links)} links ...",
                    flush=True,
                )
            await runner.up()
            if runner.stop_requested.is_set():  # stopped while it started (waiting for a place)
                return
            for line in runner.notices:  # what was cleaned up after a lab that died
                print(line, file=sys.stderr, flush=True)
            if args.json:
                print(json.dumps({"lab": lab.name, "control": runner.control_address,
                                  "links": runner.link_map()}), flush=True)  # fmt: skip
            else:
                print(link_map_text(runner.link_map(), colour))
                print(f"lab {lab.name} is up (control {runner.control_address}); Ctrl-C or "
                      f"`ktcs-bench lab down` stops it", flush=True)  # fmt: skip
            end = None if args.duration is None else loop.time() + args.duration
            last = ""
            while not runner.stop_requested.is_set():
                if end is not None and loop.time() >= end:
                    break
                for name in runner.check_children():
                    msg = f"!! {name} crashed (exit {runner.crashed[name]}): `ktcs-bench lab restart {name}` brings it back"
                    print(f"{RED}{msg}{RESET}" if colour else msg, flush=True)
                status = await runner.status()
                if args.json:
                    print(json.dumps({"status": status}), flush=True)
                else:
                    text = "\n".join([*station_lines(status, colour), *process_lines(status),
                                      *host_lines(status)])  # fmt: skip
                    if text != last:
                        print(("\x1b[2J\x1b[H" + link_map_text(runner.link_map(), colour) + "\n\n"
                               if colour else "") + text, flush=True)  # fmt: skip
                        last = text
                left = args.interval if end is None else min(args.interval, end - loop.time())
                try:
                    async with asyncio.timeout(max(0.0, left)):  # the status again, or --for ends
                        await runner.stop_requested.wait()
                except TimeoutError:
                    pass
        finally:
            await runner.down()
            if not args.json:
                print(
                    f"lab {lab.name}: stopped; every device process ended and its ptys are closed"
                )

    asyncio.run(main())
    return 128 + stopped_by[0] if stopped_by else 0


def _simulate(args: argparse.Namespace) -> int:
    import logging
    from pathlib import Path

    from ktcs_bench.lab.inprocess import InProcessLab
    from ktcs_bench.timed.vloop import VirtualDeadlock, VirtualTimeLoop

    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)
    if args.replay is not None:
        return _replay(args)
    if args.duration is None or args.out is None:
        raise UsageError("lab simulate: give --for DURATION and --out DIR (or --replay FILE)")
    watched = sys.stderr.isatty()
    with _Stop() as stop:  # Ctrl-C and SIGTERM end the run at once, and what ran is written
        lab = InProcessLab(args.lab, seed=args.seed, out=Path(args.out), invariants=True,
                           on_violation=partial(_violation, watched))  # fmt: skip

        def progress() -> None:
            s = lab.summary()
            print(f"\rvirtual {s['virtual_s']:.0f} / {args.duration:g} s, wall {s['wall_s']:.1f} s "
                  f"({s['speed_up']}x)", end="", file=sys.stderr, flush=True)  # fmt: skip

        async def main(lab: InProcessLab) -> None:
            loop = asyncio.get_running_loop()
            if watched and isinstance(loop, VirtualTimeLoop):
                loop.call_every_wall(0.5, progress)
            try:
                async with asyncio.timeout(args.duration):
                    await stop.wait()
            except TimeoutError:
                pass
            if stop.signum is not None:
                lab.interrupted = signal.Signals(stop.signum).name
            if watched:
                progress()
                print(file=sys.stderr)

        try:
            lab.run(main)
        except VirtualDeadlock as exc:
            print(f"ktcs-bench: the lab stalled: {exc}", file=sys.stderr)
            return 3
    summary = json.loads((Path(args.out) / "summary.json").read_text(encoding="utf-8"))
    from ktcs_bench.evidence.coverage import write_events_coverage  # what the run exercised

    write_events_coverage(Path(args.out), lab.topology)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"lab {summary['lab']}: {summary['virtual_s']:g} s of virtual time in "
              f"{summary['wall_s']:g} s ({summary['speed_up']}x real time), "
              f"{len(summary['violations'])} violation(s) of the lab invariants; "
              f"{args.out}/events.jsonl, {args.out}/captures/, {args.out}/summary.json, "
              f"{args.out}/coverage.json")  # fmt: skip
        for name, train in summary["trains"].items():
            print(f"  {name}: {json.dumps(train)}")
    for name, why in summary["crashed"].items():
        print(f"!! {name} crashed: {why}", file=sys.stderr)
    violations = summary["violations"]
    if violations:
        print(f"!! {len(violations)} violation(s) of the lab invariants (summary.json: "
              f"violations)", file=sys.stderr)  # fmt: skip
    if stop.signum is not None:
        print(f"interrupted ({lab.interrupted}) after {summary['virtual_s']:g} s of virtual time; "
              f"events, captures and summary are written up to there", file=sys.stderr)  # fmt: skip
        return 128 + stop.signum
    if summary["crashed"]:
        return 3
    return VIOLATIONS if violations else 0


VIOLATIONS = 1
"""`lab simulate`'s exit status when the run broke a lab invariant: "a check failed" (README)."""


def _violation(watched: bool, v: Violation) -> None:
    """One violation, one line on stderr as it is found (past the progress line, on a terminal)."""
    print(f"{CLEAR_LINE if watched else ''}!! violation: {v}", file=sys.stderr, flush=True)


CLEAR_LINE = "\r\x1b[K"


class _Stop:
    """SIGINT and SIGTERM as a request to end a lab in this process at once (`with _Stop() as
    stop:` ... `await stop.wait()` on the lab's loop; `signum`: the first that came). Python's
    own signal handlers, not the loop's: a virtual loop never waits on its wake-up pipe, where
    asyncio sees its handlers' signals; and a signal while the lab starts, before `wait`, is kept
    (`wait` returns at once)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signum: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._event: asyncio.Event | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> _Stop:
        for sig in self.SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)

    def _handle(self, signum: int, frame: object) -> None:
        if self.signum is None:
            self.signum = signum
        loop, event = self._loop, self._event
        if loop is not None and event is not None and not loop.is_closed():
            # between two steps of the loop, not inside the one this handler interrupted
            loop.call_soon_threadsafe(event.set)

    async def wait(self) -> None:
        """Until a signal comes (at once if one has)."""
        self._event = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        if self.signum is None:
            await self._event.wait()


def _replay(args: argparse.Namespace) -> int:
    """`lab simulate --replay FILE`: a saved failure of the safety search, run again."""
    from pathlib import Path

    from ktcs_bench.lab.inprocess import InProcessLab
    from ktcs_bench.lab.safety import load_replay, replay_steps

    replay = load_replay(Path(args.replay))
    lab = InProcessLab(args.lab or replay.lab, seed=replay.seed,
                       out=Path(args.out) if args.out else None, invariants=True,
                       on_violation=partial(_violation, False))  # fmt: skip
    line = lab.topology.load_line()
    runs = lab.run(lambda access: replay_steps(access, replay, line))
    found = 0
    for index, run in enumerate(runs):
        for v in run.violations:
            found += 1
            print(f"step {index} {json.dumps(dict(run.step))}: {v}")
    print(f"replay {args.replay}: lab {lab.topology.name}, seed {replay.seed}, {len(runs)} steps, "
          f"{found} violation(s)")  # fmt: skip
    return VIOLATIONS if found or lab.violations() else 0


def _up_in_process(args: argparse.Namespace) -> int:
    import logging

    from ktcs_bench.lab.inprocess import InProcessLab
    from ktcs_bench.lab.state import clean_up_after, lab_dir
    from ktcs_bench.lab.view import link_map_text, station_lines
    from ktcs_bench.runtime import private_dir, server_token

    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    spec = load_lab(resolve_lab_path(args.lab))
    for line in clean_up_after(spec.name):
        print(line, file=sys.stderr)
    private_dir(lab_dir(spec.name))
    token_file = server_token(lab_dir(spec.name) / "token")[1]
    speed = 1.0 if args.speed is None else args.speed
    lab = InProcessLab(spec, clock="scaled", speed=speed, console=True, token_file=token_file)
    colour = args.colour

    async def main(lab: InProcessLab) -> None:
        async def stop_on_signal() -> None:
            await stop.wait()
            lab.stop_requested.set()

        watch = asyncio.create_task(stop_on_signal())
        try:
            await serve(lab)
        finally:
            watch.cancel()

    async def serve(lab: InProcessLab) -> None:
        await lab.serve()
        links = lab.link_map()
        ctc = lab.ready.get(next((d.name for d in spec.of_kind(kinds.CTC)), ""), {})
        if args.json:
            print(json.dumps({"lab": spec.name, "control": lab.control_address, "links": links,
                              "console": ctc.get("console")}), flush=True)  # fmt: skip
        else:
            print(link_map_text(links, colour))
            print(f"lab {spec.name} is up in this process at {speed:g}x real time "
                  f"(control {lab.control_address}"
                  + (f", console {ctc['console']}" if ctc.get("console") else "")
                  + "); Ctrl-C or `ktcs-bench lab down` stops it", flush=True)  # fmt: skip
        end = None if args.duration is None else lab.now() + args.duration
        last = ""
        while not lab.stop_requested.is_set():
            if end is not None and lab.now() >= end:
                break
            status = await lab.status()
            if args.json:
                print(json.dumps({"status": status}), flush=True)
            else:
                text = "\n".join(station_lines(status, colour))
                if text != last:
                    print(text, flush=True)
                    last = text
            period = args.interval * speed  # the lab's clock
            left = period if end is None else min(period, end - lab.now())
            try:
                async with asyncio.timeout(max(0.0, left)):  # the status again, or --for ends
                    await lab.stop_requested.wait()
            except TimeoutError:
                pass

    with _Stop() as stop:  # a signal while the lab starts stops it as soon as it is up
        lab.run(main)
    if not args.json:
        print(f"lab {spec.name}: stopped")
    return 0 if stop.signum is None else 128 + stop.signum
