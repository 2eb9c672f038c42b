"""A group process: several devices of a live lab (one station's IXL, ATC and trackside, `lab up
--group station`) in one process and one event loop, to spare the memory of a process per device.

Each device is built from the very `ktcs-bench emulator` arguments `lab up` would start its own
process with (`lab.runner.device_args`, `emulator.build`) and launched as a lab in one process
launches it (`Device.launch`): its own control port, its own Type I ports on the lab's tap ptys,
its own rails client. Only the process and the loop are shared. The group's control port starts
and stops one device at a time, so `lab restart` and `lab kill` still act on one device: its
control port goes away and comes back, its links drop and resynchronise.

    python -m ktcs_bench.lab.group --lab FILE --name st20 [--token-file F] [--lifeline FD]

prints one ready line, {"ready": NAME, "kind": "group", "control": "HOST:PORT"}, as a device does,
and stops (every device in it) when its launcher is gone (`--lifeline`), on SIGTERM, or on `down`.
`lab up` does not start it so: it starts one template (`--template SOCKET`, `serve_template`) that
loads the lab once and forks each group process from there (`ForkedGroup`).
Commands: {"cmd": "start", "device": N, "argv": [...]} -> {"ok": true, "ready": {...}};
{"cmd": "stop", "device": N}; {"cmd": "members"} -> {"ok": true, "members": {N: "running" or why
it ended}}; {"cmd": "down"}.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import select
import signal
import socket
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from importlib import import_module
from pathlib import Path
from typing import IO, Any

from ktcs_bench.emulator.build import build_device, device_namespace
from ktcs_bench.emulator.device import Device
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.lab.processes import READY_TIMEOUT, STOP_GRACE
from ktcs_bench.lab.topology import Lab, load_lab, resolve_lab_path
from ktcs_bench.messages import JsonObject, ReadyInfo, ReadyLine
from ktcs_bench.runtime import process_alive, process_started, server_token
from ktcs_bench.transport import jsonlines, net

log = logging.getLogger("ktcs_bench.lab.group")

GROUP_KIND = "group"
"""The `kind` of a group process's ready line."""

RUNNING = "running"


class DeviceGroup:
    """The devices of one group process, each with its tasks; started and stopped one by one."""

    def __init__(self, name: str, lab: Lab) -> None:
        self.name = name
        self.lab = lab
        self.token = ""
        self.devices: dict[str, Device] = {}
        self.running: dict[str, list[asyncio.Task[None]]] = {}
        self.ended: dict[str, str] = {}  # device -> why it ended (stopped, or its task's error)
        self.stop_requested = asyncio.Event()
        self._ending: set[asyncio.Task[None]] = set()  # stops under way (held: the loop does not)

    async def start(self, name: str, argv: list[str]) -> ReadyInfo:
        """Build device `name` from its emulator arguments and launch it (stopping the one of
        that name that runs): its ready information. An OSError (a port taken) is raised."""
        if name in self.devices:
            await self.stop(name)
        args = device_namespace(argv)
        if args.name != name:
            raise UsageError(f"start {name}: its arguments name {args.name!r}")
        device: Device = build_device(args, self.lab)
        device._stop = asyncio.Event()  # its `stop` command ends it, as it ends its own process
        tasks = await device.launch(self.token)
        tasks.append(asyncio.ensure_future(self._stop_when_asked(name, device, device._stop)))
        self.devices[name], self.running[name] = device, tasks
        self.ended.pop(name, None)
        for task in tasks:
            task.add_done_callback(partial(self._task_done, name, device))
        return device.ready_info.copy()

    async def stop(self, name: str, why: str = "stopped") -> None:
        """Stop device `name` as its process's end would: its tasks cancelled (its links and
        rails dropped), its ports closed."""
        device = self.devices.pop(name, None)
        if device is None:
            return
        await device.end(self.running.pop(name, []))
        self.ended[name] = why

    def _end(self, name: str, why: str) -> None:
        """Stop device `name` from one of its own tasks (which the stop cancels: not awaited)."""
        task = asyncio.ensure_future(self.stop(name, why))
        self._ending.add(task)
        task.add_done_callback(self._ending.discard)

    async def _stop_when_asked(self, name: str, device: Device, asked: asyncio.Event) -> None:
        await asked.wait()
        if self.devices.get(name) is device:
            self._end(name, "stopped (its stop command)")

    def _task_done(self, name: str, device: Device, task: asyncio.Task[None]) -> None:
        """A device whose task failed ends, as its process would end (exit 3); the others run on."""
        if task.cancelled() or self.devices.get(name) is not device:
            return
        exc = task.exception()
        if exc is not None:
            log.error("%s: %s", name, exc)
            self._end(name, f"crashed: {type(exc).__name__}: {exc}")

    def members(self) -> dict[str, str]:
        return {**self.ended, **dict.fromkeys(self.devices, RUNNING)}

    async def command(self, obj: Mapping[str, object]) -> dict[str, Any]:
        cmd = obj.get("cmd")
        try:
            if cmd == "start":
                argv = obj["argv"]
                if not isinstance(argv, list):
                    raise UsageError("start: argv is a list of arguments")
                ready = await self.start(str(obj["device"]), [str(a) for a in argv])
                return {"ok": True, "ready": ready}
            if cmd == "stop":
                await self.stop(str(obj["device"]), str(obj.get("why") or "stopped"))
                return {"ok": True}
            if cmd == "members":
                return {"ok": True, "members": self.members()}
            if cmd == "down":
                self.stop_requested.set()
                return {"ok": True}
        except KeyError as exc:
            return {"ok": False, "error": f"{cmd}: missing {exc}"}
        except (KtcsError, OSError) as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": False, "error": f"unknown command {cmd!r} (start, stop, members, down)"}

    async def _handle(self, obj: JsonObject, peer: jsonlines.Peer) -> dict[str, Any]:
        return await self.command(obj)

    async def run(self, token_file: str | None, lifeline: int | None, out: IO[str]) -> int:
        """Serve the group's control port until asked to stop or the launcher is gone; then stop
        every device in it. Its ready line goes to `out`."""
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, self.stop_requested.set)
        if lifeline is not None:
            os.set_blocking(lifeline, False)
            loop.add_reader(lifeline, partial(self._lifeline_readable, lifeline))
        self.token = server_token(token_file)[0]
        try:
            server = await jsonlines.serve("127.0.0.1", 0, self._handle, token=self.token)
        except OSError as exc:
            out.write(json.dumps({"error": str(exc)}) + "\n")
            out.flush()
            return 3
        host, port = net.server_address(server)
        ready = {"ready": self.name, "kind": GROUP_KIND, "control": f"{host}:{port}",
                 "pid": os.getpid()}  # fmt: skip
        out.write(json.dumps(ready) + "\n")
        out.flush()
        try:
            await self.stop_requested.wait()
        finally:
            server.close()
            await asyncio.gather(*(self.stop(n) for n in list(self.devices)))
        return 0

    def _lifeline_readable(self, fd: int) -> None:
        try:
            data = os.read(fd, 64)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            asyncio.get_running_loop().remove_reader(fd)
            log.warning("%s: the process that started it is gone; stopping", self.name)
            self.stop_requested.set()


def template_argv(lab: Lab, socket_path: Path, token_file: str | None) -> list[str]:
    """The command line of the group template of `lab` (`lab.processes.Child` adds its
    lifeline): the process that loads the lab once and forks a group process per request on
    `socket_path` (`serve_template`)."""
    argv = [sys.executable, "-m", "ktcs_bench.lab.group", "--lab", str(lab.file),
            "--template", str(socket_path)]  # fmt: skip
    return argv + (["--token-file", token_file] if token_file else [])


def serve_template(lab: Lab, socket_path: str, token_file: str | None, lifeline: int | None) -> int:
    """Fork a group process for each request on `socket_path` ({"fork": NAME}), which answers on
    that connection with its ready line. The template imports the devices' modules and loads the
    lab and its line before it forks, so a group process starts with all of it (about 0.3 s of
    CPU an interpreter and its line would take again). It forks from no event loop and no
    thread; it stops when its launcher is gone (`lifeline`) or on SIGTERM."""
    lab.load_line()
    import_module("ktcs_bench.emulator.ixl")
    import_module("ktcs_bench.emulator.atc")
    import_module("ktcs_bench.emulator.trackside")
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # the kernel reaps the groups
    with contextlib.suppress(FileNotFoundError):
        os.unlink(socket_path)
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(socket_path)
    server.listen(16)
    sys.stdout.write(json.dumps({"ready": "template", "kind": "template", "control": ""}) + "\n")
    sys.stdout.flush()
    watched = [server] + ([lifeline] if lifeline is not None else [])
    while True:
        readable, _, _ = select.select(watched, [], [])
        if lifeline is not None and lifeline in readable and not os.read(lifeline, 64):
            return 0
        if server not in readable:
            continue
        conn, _ = server.accept()
        with conn:
            line = conn.makefile("r").readline()
            try:
                name = str(json.loads(line)["fork"])
            except (ValueError, KeyError, TypeError):
                continue
            if os.fork() == 0:  # the group process
                code = 3
                try:
                    server.close()
                    os.setsid()  # its own process group, as `lab up`'s children are
                    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                    out = conn.makefile("w")
                    code = asyncio.run(DeviceGroup(name, lab).run(token_file, lifeline, out))
                finally:
                    os._exit(code)


@dataclass
class Forked:
    """A forked group process's id, as `subprocess.Popen` gives a started one's."""

    pid: int


@dataclass
class ForkedGroup:
    """A group process forked by the lab's template (`serve_template`), seen as `lab.processes
    .Child` sees a process it started: `start` (blocking) asks the template for it and returns
    its ready line; alive while its pid runs with its start time; `stop` SIGTERM then SIGKILL."""

    name: str
    socket_path: Path
    ready: ReadyLine = field(default_factory=lambda: ReadyLine())
    proc: Forked | None = None
    started: int | None = None
    exit_code: int | None = None

    def start(self) -> ReadyLine:
        self.stop()
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(READY_TIMEOUT)
            sock.connect(str(self.socket_path))
            sock.sendall(json.dumps({"fork": self.name}).encode() + b"\n")
            line = sock.makefile("r").readline()
        try:
            ready = json.loads(line)
        except ValueError:
            ready = None
        if not isinstance(ready, dict) or "error" in ready or "pid" not in ready:
            why = ready.get("error") if isinstance(ready, dict) else "no ready line"
            raise PeerError(f"{self.name} did not start: {why}")
        self.proc = Forked(int(ready.pop("pid")))
        self.started, self.exit_code = process_started(self.proc.pid), None
        self.ready = ReadyLine(ready=self.name, kind=GROUP_KIND, control=str(ready["control"]))
        return self.ready

    @property
    def alive(self) -> bool:
        return self.proc is not None and process_alive(self.proc.pid, self.started)

    def poll(self) -> int | None:
        if self.proc is None or self.exit_code is not None or self.alive:
            return None
        self.exit_code = -signal.SIGKILL  # its exit status went to the template, which reaped it
        return self.exit_code

    def stop(self, sig: int = signal.SIGTERM) -> None:
        for s in (sig, signal.SIGKILL):
            if not self.alive:
                return
            assert self.proc is not None
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, s)
            end = time.monotonic() + STOP_GRACE
            while self.alive and time.monotonic() < end:
                time.sleep(0.02)

    def kill(self) -> None:
        self.stop(signal.SIGKILL)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m ktcs_bench.lab.group")
    p.add_argument("--lab", required=True, help="the lab file")
    p.add_argument("--name", help="the group's name (st20: station 20's)")
    p.add_argument("--template", metavar="SOCKET",
                   help="be the lab's group template: fork a group per request on SOCKET")  # fmt: skip
    p.add_argument("--token-file", help="the token its control port and its devices' require")
    p.add_argument("--lifeline", type=int, help="stop at end of file on this descriptor")
    p.add_argument("-v", "--verbose", action="store_true", help="log every event to stderr")
    args = p.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )  # fmt: skip
    try:
        lab = load_lab(resolve_lab_path(args.lab))
    except KtcsError as exc:
        sys.stdout.write(json.dumps({"error": str(exc)}) + "\n")
        return 2
    if args.template:
        return serve_template(lab, args.template, args.token_file, args.lifeline)
    if not args.name:
        p.error("--name or --template is required")
    group = DeviceGroup(args.name, lab)
    code: int = asyncio.run(group.run(args.token_file, args.lifeline, sys.stdout))
    return code


if __name__ == "__main__":
    sys.exit(main())
