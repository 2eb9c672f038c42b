"""`lab up`: start a lab's devices as processes, put taps in its links, watch them, report status.

Order of start: the track-circuit emulator (the rails) and the CTC (the Type II server), the taps
(a pty pair per Type I end; a TCP proxy per Type II link), then every station's ATC and trackside
I/O, then the IXLs, then the trains. The devices of one step start together (a few at a time, as
the machine has cores), none waiting for another's ready line: nothing one needs comes from
another of its step. Every device is `ktcs-bench emulator KIND ...` -- the same command a user runs
to put one device on another machine -- so the lab assumes nothing the devices do not.

`--group station` (`LabRunner.group`) puts the devices of one station -- its IXL, ATC and
trackside -- in one process (`lab.group`), built from those same arguments, to spare a process's
memory per device; their Type I links still run over the taps' ptys. The station processes are
forked from one template process that has loaded the lab (`lab.group.serve_template`), which spares
each the start of an interpreter and the load of its line. Such a device is a
`GroupMember`: started, stopped and killed one at a time through its group process's control
port, so `restart` and `kill` still act on one device. `--group none` (a process per device, the
default) keeps the fidelity of separate processes.

An external device (a real one, `external:` in the lab file) is not started: its link's tap opens
its serial endpoint as that end (Type I), connects to it (a CTC) or serves the address it connects
to (an IXL). It is alive while that link is up, as the device of ours at the other end sees it;
`restart` and `kill` refuse it (the lab does not run it). One shared through labgrid (`external:
{labgrid: PLACE}`) is acquired first and released when the lab ends, however it ends
(`lab.labgrid.Places`); its exported serial port is its endpoint.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Awaitable, Coroutine, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypedDict, TypeVar
from urllib.parse import urlsplit

from ktcs_bench import kinds
from ktcs_bench.capture import open_writer
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.lab.group import ForkedGroup, template_argv
from ktcs_bench.lab.labgrid import Places
from ktcs_bench.lab.processes import READY_TIMEOUT, Child, emulator_argv
from ktcs_bench.lab.state import clean_up_after, lab_dir, read_state, state_file, write_state
from ktcs_bench.lab.topology import Lab, LinkSpec
from ktcs_bench.lab.view import LinkEntry
from ktcs_bench.messages import JsonObject, ReadyInfo, ReadyLine
from ktcs_bench.runtime import private_dir, server_token, this_process
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.runner import Tap, TapStatus
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.transport import jsonlines

log = logging.getLogger("ktcs_bench.lab")
T = TypeVar("T")

# devices a live lab starts at once: a start is mostly the interpreter's CPU (imports, line data)
STARTS_AT_ONCE = max(4, 2 * (os.cpu_count() or 1))

GROUPINGS = ("none", "station")
"""How `lab up` puts devices in processes (`--group`): one each, or one per station."""

KILLED = -9  # what a killed device's process exits with (SIGKILL): `lab kill` of a member too


def device_args(
    lab: Lab,
    name: str,
    *,
    before: ReadyInfo,
    endpoints: dict[str, str],
    token_file: Path | None,
    unpaced: bool = False,
    console: bool = True,
) -> list[str]:
    """The arguments of `ktcs-bench emulator` for device `name` of `lab` -- what `lab up` starts
    a process with, and what a lab in one process builds the device object from
    (`emulator.build.build_device`). A device started before (a restart) gets back the addresses it
    had (`before`: its ready line) -- control port, Type II / rails port, console -- so the taps in
    front of it, the devices that reach it and the clients that know it find it again where it
    was. `endpoints`: its links, role -> endpoint."""
    d = lab.devices[name]
    argv = [d.kind, "--lab", str(lab.file), "--name", name,
            "--control", before.get("control") or f"{d.host}:0"]  # fmt: skip
    if token_file is not None:
        argv += ["--token-file", str(token_file)]
    if d.station is not None:
        argv += ["--station", str(d.station)]
    if unpaced:
        argv.append("--unpaced")
    for role, ep in endpoints.items():
        argv += ["--link", f"{role}={ep}"]
    if d.kind == kinds.TRACKCIRCUIT:
        argv += ["--listen", before.get("listen") or f"{d.host}:{d.options.get('port', 0)}"]
    if d.kind == kinds.CTC:
        argv += ["--listen", before.get("listen") or f"{d.host}:{lab.type2_port}"]
        if lab.console_port is not None and console:
            url = urlsplit(str(before.get("console", "")))
            port = url.port if url.port is not None else lab.console_port
            argv += ["--console", f"{d.host}:{port}"]
            argv += [arg for o in lab.console_origins for arg in ("--console-origin", o)]
            argv += [arg for lk in lab.links if lk.tap for arg in ("--tap", lk.name)]
    if d.kind == kinds.IXL and before:  # restarted in a running lab: start-up locking
        argv.append("--restarted")
    if d.kind == kinds.TRAIN and kinds.TRAIN in d.options:
        argv += ["--train", str(d.options[kinds.TRAIN])]
    return argv


class ProcessJson(TypedDict):
    """The process a device lives in (`lab status`): its own, or its station's group's."""

    pid: int | None
    name: str


class LabStarter(Protocol):
    """How a lab makes its links and starts its devices (`start_in_order`): as processes on
    ptys and TCP (`LabRunner`), or as objects in one process (`inprocess.InProcessLab`)."""

    async def _start(self, name: str) -> ReadyInfo:
        """Start device `name` (its endpoints are set); its ready line."""
        ...

    async def type2_end(self, link: LinkSpec, index: int, ctc: tuple[str, int]) -> str:
        """The endpoint the IXL of Type II `link` connects to (a tap's, or the CTC's own)."""
        ...

    async def type1_ends(self, link: LinkSpec, index: int) -> tuple[str, str] | None:
        """The endpoints of Type I `link` for its a and b ends; None (a link with no tap): the IXL
        makes a pty and the peer starts after it, on the path it reports (or the IXL opens an
        external peer's line)."""
        ...


async def start_in_order(
    lab: Lab, starter: LabStarter, endpoints: dict[str, dict[str, str]], together: bool = False
) -> None:
    """Start a lab's devices in the order every lab starts them, filling in `endpoints` (device ->
    role -> endpoint) on the way: the track circuits (the rails) and the CTC (the Type II server),
    the links (taps), every station's ATC and trackside I/O, the IXLs (each followed by the peers
    on its untapped ptys), then the trains. An external device is not started: a real CTC's
    address is the Type II target, a real Type I peer's serial line is the IXL's (or its tap's)
    end. `together`: the devices of one step start at once, not one after another."""

    async def step(*starts: Coroutine[Any, Any, T]) -> list[T]:
        if together:
            return await _together(*starts)
        try:
            return [await s for s in starts]
        finally:
            for s in starts:
                s.close()  # those not run after one failed (a no-op on those that ran)

    async def ixl_and_peers(ixl: str) -> None:
        ready = await starter._start(ixl)
        peers = [peer for peer, lk in untapped.items() if lk.a == ixl]
        for peer in peers:
            role = lab.peer_role(untapped[peer], ixl)
            endpoints.setdefault(peer, {})[kinds.IXL] = ready["ptys"][role]
        await step(*(starter._start(p) for p in peers))

    ctc_address = None
    first = list(lab.of_kind(kinds.TRACKCIRCUIT))
    for ctc in lab.of_kind(kinds.CTC):
        if ctc.external is not None and ctc.external.address is not None:
            ctc_address = ctc.external.address  # a real CTC, serving there
        else:
            first.append(ctc)
    rails = None
    for d, ready in zip(first, await step(*(starter._start(d.name) for d in first)), strict=True):
        if d.kind == kinds.TRACKCIRCUIT:
            rails = ready["listen"]
        else:
            host, _, port = ready["listen"].rpartition(":")
            ctc_address = (host, int(port))
    untapped: dict[str, LinkSpec] = {}
    for index, link in enumerate(lab.links):
        a, b = link.a, link.b
        ea, eb = endpoints.setdefault(a, {}), endpoints.setdefault(b, {})
        role_b, role_a = lab.peer_role(link, a), lab.peer_role(link, b)
        if link.type == "type2":
            if ctc_address is None:
                raise UsageError(f"link {link.name}: the lab has no CTC")
            ea[role_b] = await starter.type2_end(link, index, ctc_address)
        elif (ends := await starter.type1_ends(link, index)) is not None:
            ea[role_b], eb[role_a] = ends
        elif (ext := lab.devices[b].external) is not None:
            ea[role_b] = str(ext.serial)  # the IXL opens the real line itself
        else:
            ea[role_b] = "pty"
            untapped[b] = link
    if rails is not None:
        for d in lab.devices.values():
            if kinds.KINDS[d.kind].rails and d.external is None:
                endpoints.setdefault(d.name, {})[kinds.RAILS] = f"tcp://{rails}"
    ours = [d.name for d in lab.devices.values() if d.external is None]
    group = {n: kinds.KINDS[lab.devices[n].kind].start for n in ours}
    ixl_group = kinds.KINDS[kinds.IXL].start
    for g in sorted({g for g in group.values() if g}):
        if g == ixl_group:  # each IXL followed by the peers on its untapped ptys
            await step(*(ixl_and_peers(n) for n in ours if group[n] == g))
        else:
            await step(*(starter._start(n) for n in ours if group[n] == g and n not in untapped))


async def _together(*starts: Awaitable[T]) -> list[T]:
    """Run these starts at once; their results, in order. One that fails fails the whole, raised
    once every start has ended, so no device is left half started when the lab stops."""
    results = await asyncio.gather(*starts, return_exceptions=True)
    for result in results:
        if isinstance(result, BaseException):
            raise result
    return [r for r in results if not isinstance(r, BaseException)]


class LabCommands(Protocol):
    """What a lab offers its own control port (`lab_command`), live or in one process."""

    stop_requested: asyncio.Event

    async def status(self) -> dict[str, Any]: ...

    def link_map(self) -> list[LinkEntry]: ...

    async def restart(self, name: str) -> None: ...

    async def kill(self, name: str) -> None: ...


async def lab_command(lab: LabCommands, obj: Mapping[str, object]) -> dict[str, Any]:
    """The lab's own commands -- status, map, restart, kill, down -- and their answers."""
    cmd = obj.get("cmd")
    try:
        if cmd == "status":
            return {"ok": True, "status": await lab.status()}
        if cmd == "map":
            return {"ok": True, "links": lab.link_map()}
        if cmd == "restart":
            await lab.restart(str(obj["device"]))
            return {"ok": True}
        if cmd == "kill":
            await lab.kill(str(obj["device"]))
            return {"ok": True}
        if cmd == "down":
            lab.stop_requested.set()
            return {"ok": True}
    except KeyError as exc:
        return {"ok": False, "error": f"{cmd}: missing {exc}"}
    except (KtcsError, OSError) as exc:  # a device that does not come back, a port taken
        return {"ok": False, "error": str(exc)}
    return {"ok": False, "error": f"unknown command {cmd!r} (status, map, restart, kill, down)"}


@dataclass
class GroupMember:
    """A device living in a group process, seen as `Child` sees a device process: alive while it
    runs there and its process lives; `poll` reports once how it ended (killed, crashed, or its
    process gone)."""

    name: str
    group: ForkedGroup
    ready: ReadyLine = field(default_factory=lambda: ReadyLine())
    running: bool = False
    _ended: int | None = None  # how it ended, not reported yet

    @property
    def proc(self) -> Any:
        return self.group.proc

    @property
    def started(self) -> int | None:
        return self.group.started

    @property
    def alive(self) -> bool:
        return self.running and self.group.alive

    def ended(self, code: int) -> None:
        if self.running:
            self.running, self._ended = False, code

    def poll(self) -> int | None:
        if self.running and not self.group.alive:
            self.ended(self.group.exit_code if self.group.exit_code is not None else KILLED)
        code, self._ended = self._ended, None
        return code


@dataclass
class LabRunner:
    lab: Lab
    unpaced: bool = False
    capture: bool = True
    console: bool = True
    group: str = "none"  # GROUPINGS: "station" runs a station's devices in one process
    children: dict[str, Child | GroupMember] = field(default_factory=dict)
    groups: dict[str, ForkedGroup] = field(default_factory=dict)  # group processes (st20)
    template: Child | None = None  # the process that forks the group processes
    taps: dict[str, Tap] = field(default_factory=dict)
    endpoints: dict[str, dict[str, str]] = field(default_factory=dict)  # device -> role -> endpoint
    control_address: str = ""
    crashed: dict[str, int] = field(default_factory=dict)
    notices: list[str] = field(default_factory=list)
    stop_requested: asyncio.Event = field(default_factory=asyncio.Event)
    token: str = ""  # what every control port of this lab requires (runtime)
    token_file: Path | None = None
    _starting: asyncio.Semaphore = field(default_factory=lambda: asyncio.Semaphore(STARTS_AT_ONCE))
    _group_locks: dict[str, asyncio.Lock] = field(default_factory=dict)
    wait_for_place: float | None = None  # a held labgrid place: None an error, else wait (s, inf)
    places: Places | None = None  # the labgrid places it holds

    @property
    def dir(self) -> Path:
        return lab_dir(self.lab.name)

    # -- start -------------------------------------------------------------------------------
    def _args(self, name: str) -> list[str]:
        """The device's emulator arguments (`device_args`), with what it had before if it ran."""
        before = self.children[name].ready if name in self.children else {}
        return device_args(
            self.lab, name, before=before, endpoints=self.endpoints.get(name, {}),
            token_file=self.token_file, unpaced=self.unpaced, console=self.console,
        )  # fmt: skip

    def _argv(self, name: str) -> list[str]:
        """The device's command line."""
        return emulator_argv(*self._args(name))

    def group_of(self, name: str) -> str | None:
        """The group process device `name` lives in (None: a process of its own)."""
        d = self.lab.devices[name]
        if self.group != "station" or d.station is None or d.external is not None:
            return None
        return f"st{d.station}" if kinds.KINDS[d.kind].station else None

    async def _start(self, name: str) -> ReadyLine:
        group = self.group_of(name)
        if group is not None:
            return await self._start_member(name, group)
        old = self.children.get(name)
        child = (
            old if isinstance(old, Child) else Child(name, [], self.dir / "logs" / f"{name}.log")
        )
        child.argv = self._argv(name)
        self.children[name] = child
        async with self._starting:
            try:
                ready = await asyncio.to_thread(child.start)
            finally:
                self._write_state()
        self.crashed.pop(name, None)
        return ready

    async def _start_member(self, name: str, group: str) -> ReadyLine:
        """Start device `name` in its group process (starting that first if it is not running)."""
        process = await self._group_process(group)
        argv = self._args(name)
        answer = await self._group_request(
            process, {"cmd": "start", "device": name, "argv": argv}, READY_TIMEOUT
        )
        ready = answer.get("ready")
        if not isinstance(ready, dict):
            raise PeerError(f"{name} did not start in {group}: {answer.get('error')}")
        old = self.children.get(name)
        member = old if isinstance(old, GroupMember) else GroupMember(name, process)
        member.group, member.running = process, True
        member.poll()  # how it ended before is no news now
        member.ready = ReadyLine(ready=name, kind=self.lab.devices[name].kind, **ready)  # type: ignore[typeddict-item]
        self.children[name] = member
        self.crashed.pop(name, None)
        self._write_state()
        return member.ready

    async def _group_process(self, group: str) -> ForkedGroup:
        """Group process `group`, started if it is not running: forked by the lab's template
        (started first if it is not running), which has loaded the lab and its line already."""
        async with self._group_locks.setdefault(group, asyncio.Lock()):
            child = self.groups.get(group)
            if child is not None and child.alive:
                return child
            async with self._group_locks.setdefault("", asyncio.Lock()):
                if self.template is None or not self.template.alive:
                    self.template = self.template or Child(
                        "groups", [], self.dir / "logs" / "groups.log"
                    )
                    self.template.argv = template_argv(
                        self.lab, self._template_socket, str(self.token_file or "") or None
                    )
                    await asyncio.to_thread(self.template.start)
            child = child or ForkedGroup(group, self._template_socket)
            self.groups[group] = child
            async with self._starting:
                await asyncio.to_thread(child.start)
            return child

    @property
    def _template_socket(self) -> Path:
        return self.dir / "groups.sock"

    async def _group_request(
        self, process: ForkedGroup, obj: dict[str, Any], timeout: float = 10.0
    ) -> dict[str, Any]:
        """A command to a group process's control port; PeerError when it says no."""
        host, _, port = process.ready["control"].rpartition(":")
        answer = await jsonlines.request(host, int(port), obj, timeout=timeout, token=self.token)
        if not answer.get("ok"):
            raise PeerError(f"{process.name}: {answer.get('error')}")
        return answer

    async def _stop_device(self, name: str, why: str = "stopped", code: int = 0) -> None:
        """Stop device `name`: its process, or its part of its group process."""
        child = self.children[name]
        if isinstance(child, Child):
            await asyncio.to_thread(child.kill if code == KILLED else child.stop)
            return
        if child.group.alive:
            await self._group_request(child.group, {"cmd": "stop", "device": name, "why": why})
        child.ended(code)
        if code == 0:
            child.poll()  # stopped on purpose: not a crash to report

    async def _refresh_members(self) -> None:
        """Learn from each group process which of its devices ended there (a task's error)."""
        for process in self.groups.values():
            if not process.alive:
                continue
            try:
                members = (await self._group_request(process, {"cmd": "members"}))["members"]
            except (OSError, TimeoutError, KtcsError, KeyError):
                continue
            for name, state in members.items():
                member = self.children.get(name)
                if isinstance(member, GroupMember) and state != "running" and member.running:
                    if str(state).startswith("crashed"):
                        self.notices.append(f"{name} {state}")
                        member.ended(3)
                    else:
                        member.ended(0)

    async def type2_end(self, link: LinkSpec, index: int, ctc: tuple[str, int]) -> str:
        if not link.tap:
            return f"tcp://{ctc[0]}:{ctc[1]}"
        tap = self.taps[link.name] = self._tap_for(link, ctc)
        assert isinstance(tap, TcpTap) and tap.listen_address is not None
        return f"tcp://{tap.listen_address[0]}:{tap.listen_address[1]}"

    async def type1_ends(self, link: LinkSpec, index: int) -> tuple[str, str] | None:
        if not link.tap:
            return None
        tap = self.taps[link.name] = self._tap_for(link, None)
        assert isinstance(tap, PtyTap)
        b = link.b
        if b not in tap.external:
            return tap.paths[link.a], tap.paths[b]
        if not tap.external_open(b):  # the tap opens the real device's serial line itself
            error = tap.external_error(b)
            self.notices.append(f"{link.name}: {b} (external) is not there yet at "
                                f"{tap.external[b]} ({error}); the tap keeps trying")  # fmt: skip
        return tap.paths[link.a], tap.external[b]

    def _tap_for(self, link: LinkSpec, ctc_address: tuple[str, int] | None) -> Tap:
        names = (link.a, link.b)
        ext_a, ext_b = self.lab.devices[link.a].external, self.lab.devices[link.b].external
        writers = []
        if self.capture:
            kind = "type1" if link.type == "type1" else "type2"
            writers.append(open_writer(str(self.dir / "captures" / f"{link.name}.hex"), link=kind))
        if link.type == "type1":
            external = {link.b: str(ext_b.serial)} if ext_b is not None else {}
            tap: Tap = PtyTap(names=names, profile=self.lab.type1_profile, name=link.name,
                              writers=writers, token_file=self.token_file, external=external,
                              line_rate=None if self.unpaced else self.lab.line_rate)  # fmt: skip
        else:
            assert ctc_address is not None
            # a real IXL connects to the address its entry gives; ours to any free port
            listen = ext_a.address if ext_a is not None else None
            listen = listen or (self.lab.devices[link.a].host, 0)
            tap = TcpTap(listen, ctc_address, names=names, profile=self.lab.type2_profile,
                         name=link.name, writers=writers, token_file=self.token_file)  # fmt: skip
        tap.start()  # a named tap announces itself in the registry
        return tap

    async def up(self) -> None:
        """Start everything. A lab of this name that died without stopping is cleaned up first
        (its leftover devices stopped, its taps dropped); one that is up is a UsageError."""
        self.notices += await asyncio.to_thread(clean_up_after, self.lab.name)
        private_dir(self.dir / "logs")
        private_dir(self.dir / "captures")
        self.token, self.token_file = server_token(self.token_file or self.dir / "token")
        self.places = Places(self.dir / "logs", self.wait_for_place)  # shared real devices first
        self.lab = await self.places.acquire(self.lab, self.stop_requested)
        if self.stop_requested.is_set():  # stopped while it waited for a place
            return
        self._write_state()  # from now on, whatever kills this lab, the next one can clean up
        # the group processes need nothing of the others: they start beside the first step
        groups = {g for n in self.lab.devices if (g := self.group_of(n)) is not None}
        early = asyncio.ensure_future(_together(*(self._group_process(g) for g in sorted(groups))))
        try:
            await start_in_order(self.lab, self, self.endpoints, together=True)
        finally:
            await asyncio.gather(early, return_exceptions=True)
        early.result()  # a group process that did not start fails the lab's start
        await self._trains_to_ctc()
        await self._serve_control()
        self._write_state()

    async def _trains_to_ctc(self) -> None:
        """Tell the CTC of every train process, whose curves its console draws."""
        for ctc in self.lab.ours(kinds.CTC):
            host, _, port = self.children[ctc.name].ready["control"].rpartition(":")
            for d in self.lab.of_kind(kinds.TRAIN):
                train, ready = str(d.options.get(kinds.TRAIN, d.name)), self.children[d.name].ready
                await jsonlines.request(host, int(port),
                                        {"cmd": "add_train", kinds.TRAIN: train, "control": ready["control"]},
                                        token=self.token)  # fmt: skip

    # -- control port and state file ---------------------------------------------------------------
    async def _serve_control(self) -> None:
        self._control = await jsonlines.serve("127.0.0.1", 0, self._handle, token=self.token)
        host, port = self._control.sockets[0].getsockname()[:2]
        self.control_address = f"{host}:{port}"

    def _write_state(self) -> None:
        state = {
            "lab": self.lab.name,
            "file": str(self.lab.file),
            **this_process(),
            "control": self.control_address,
            "token_file": str(self.token_file),
            "devices": {
                # a device by pid and start time together (one starting has no start time yet)
                n: {
                    "pid": c.proc.pid if c.proc and c.started is not None else None,
                    "started": c.started,
                    **c.ready,
                    **({"process": c.group.name} if isinstance(c, GroupMember) else {}),
                }
                for n, c in self.children.items()
            },
            "links": self.link_map(),
        }
        write_state(self.lab.name, state)

    async def _handle(self, obj: JsonObject, peer: jsonlines.Peer) -> dict[str, Any]:
        return await lab_command(self, obj)

    async def kill(self, name: str) -> None:
        """As a crash would: SIGKILL to its process; a device of a group process is stopped there
        at once, the others of its group run on."""
        self._refuse_external(name, "kill")
        self._child(name)
        await self._stop_device(name, "killed", KILLED)

    def _refuse_external(self, name: str, what: str) -> None:
        d = self.lab.devices.get(name)
        if d is not None and d.external is not None:
            raise UsageError(
                f"{name} is external (a real device at {d.external.endpoint}): the lab does not "
                f"run it and cannot {what} it; {what} it where it runs -- its link comes back "
                "through the tap when it is there again"
            )

    def _child(self, name: str) -> Child | GroupMember:
        if name not in self.children:
            raise UsageError(
                f"no device {name!r} in lab {self.lab.name} ({', '.join(self.children)})"
            )
        return self.children[name]

    async def restart(self, name: str) -> None:
        """Stop (if it still runs) and start a device again, at the addresses it had. What cannot
        keep its address is re-pointed: an IXL makes new ptys for its untapped Type I links, so
        the peers on them restart on the new paths; a new CTC learns the trains again."""
        self._refuse_external(name, "restart")
        self._child(name)
        await self._stop_device(name)
        ready = await self._start(name)
        kind = self.lab.devices[name].kind
        if kind == kinds.IXL:
            for lk in self.lab.links:
                if lk.a == name and lk.type == "type1" and not lk.tap and lk.b in self.children:
                    role = self.lab.peer_role(lk, name)
                    self.endpoints.setdefault(lk.b, {})[kinds.IXL] = ready["ptys"][role]
                    await self._stop_device(lk.b)
                    await self._start(lk.b)
        if kind == kinds.CTC:
            await self._trains_to_ctc()
        self.notices.append(f"{name} restarted")
        self._write_state()

    # -- watching ----------------------------------------------------------------------------------
    def check_children(self) -> list[str]:
        """Newly crashed devices (reported once each)."""
        out = []
        for name, child in self.children.items():
            code = child.poll()
            if code is not None and name not in self.crashed:
                self.crashed[name] = code
                out.append(name)
        return out

    async def device_status(self, name: str) -> dict[str, Any] | None:
        child = self.children[name]
        if not child.alive or "control" not in child.ready:
            return None
        host, _, port = child.ready["control"].rpartition(":")
        try:
            answer = await jsonlines.request(
                host, int(port), {"cmd": "status"}, timeout=2.0, token=self.token
            )
        except (OSError, TimeoutError, ValueError, KtcsError):
            return None
        status = answer.get("status")
        return status if isinstance(status, dict) else None

    def process_of(self, name: str) -> ProcessJson:
        """The process device `name` lives in: its pid and name (its own, or its group's)."""
        child = self.children[name]
        process = child.group if isinstance(child, GroupMember) else child
        return {"pid": process.proc.pid if process.proc else None, "name": process.name}

    async def status(self) -> dict[str, Any]:
        await self._refresh_members()
        names = list(self.children)
        results = await asyncio.gather(*(self.device_status(n) for n in names))
        devices = dict(zip(names, results, strict=True))
        ctc = next(
            (s for n, s in devices.items() if self.lab.devices[n].kind == kinds.CTC and s), None
        )
        taps = {n: t.status() for n, t in self.taps.items()}
        out = {
            "lab": self.lab.name,
            "stations": (ctc or {}).get("stations", {}),
            "devices": {
                n: {
                    "alive": self.children[n].alive,
                    "crashed": self.crashed.get(n),
                    "status": s,
                    "process": self.process_of(n),
                }
                for n, s in devices.items()
            },
            "taps": taps,
        }
        for d in self.lab.devices.values():
            if d.external is not None:
                links = {
                    lk.name: self._link_up(lk, devices, taps) for lk in self.lab.links_of(d.name)
                }
                out["devices"][d.name] = {
                    "alive": bool(links) and all(links.values()), "crashed": None, "status": None,
                    "external": d.external.endpoint, "links": links,
                }  # fmt: skip
        return out

    def _link_up(self, link: LinkSpec, devices: dict[str, Any], taps: dict[str, TapStatus]) -> bool:
        """Whether `link` is up, as the device of ours on it sees it: the IXL's link to that peer,
        or the CTC's to that station; between two external devices, the tap's connection."""
        a, b = self.lab.devices[link.a], self.lab.devices[link.b]
        if a.external is None:
            role = self.lab.peer_role(link, a.name)
            return bool(((devices.get(a.name) or {}).get("links") or {}).get(role))
        stations = (devices.get(b.name) or {}).get("stations") or {}
        if b.external is None:
            summary = stations.get(a.station) or stations.get(str(a.station)) or {}
            return summary.get("link") == "up"
        tap = taps.get(link.name)
        return tap is not None and bool(tap.get("connected"))

    def link_map(self) -> list[LinkEntry]:
        out: list[LinkEntry] = []
        for link in self.lab.links:
            tap = self.taps.get(link.name)
            entry: LinkEntry = {"link": link.name, "type": link.type, "a": link.a, "b": link.b}
            if isinstance(tap, PtyTap):
                entry["a_end"] = tap.paths[link.a]
                entry["b_end"] = tap.paths.get(link.b) or tap.external[link.b]
            elif isinstance(tap, TcpTap) and tap.listen_address:
                entry["a_end"] = f"tcp://{tap.listen_address[0]}:{tap.listen_address[1]}"
                entry["b_end"] = f"tcp://{tap.target[0]}:{tap.target[1]}"
            else:
                entry["a_end"] = self.endpoints.get(link.a, {}).get(
                    self.lab.peer_role(link, link.a), ""
                )
            external = [n for n in (link.a, link.b) if self.lab.devices[n].external is not None]
            if external:
                entry["external"] = external
            if tap is not None and tap.control_address:
                entry["tap"] = f"{tap.control_address[0]}:{tap.control_address[1]}"
            if self.capture:
                entry["capture"] = str(self.dir / "captures" / f"{link.name}.hex")
            out.append(entry)
        for name, child in self.children.items():
            if "listen" in child.ready:
                out.append({"link": f"{name} listens", "type": self.lab.devices[name].kind,
                            "a_end": child.ready["listen"]})  # fmt: skip
            if "console" in child.ready:
                out.append(
                    {"link": f"{name} console", "type": "web", "a_end": child.ready["console"]}
                )
        return out

    # -- stop --------------------------------------------------------------------------------------
    async def down(self) -> None:
        ixls = [n for n, c in self.children.items() if self.lab.devices[n].kind == kinds.IXL]
        alone = [c for n, c in self.children.items() if isinstance(c, Child) and n not in ixls]
        await asyncio.gather(*(self._stop_device(n) for n in ixls), return_exceptions=True)
        await asyncio.gather(
            *(asyncio.to_thread(c.stop) for c in alone),
            *(asyncio.to_thread(g.stop) for g in self.groups.values()),
        )
        if self.template is not None:
            await asyncio.to_thread(self.template.stop)
        for tap in self.taps.values():
            tap.stop()  # closes its pty pairs (the ptys are gone) and withdraws it
        if getattr(self, "_control", None) is not None:
            self._control.close()
        if self.places is not None:  # after the taps: the device's port is closed, then given back
            for problem in await asyncio.to_thread(self.places.release):
                log.warning(problem)
        if (read_state(self.lab.name) or {}).get("pid") == os.getpid():  # ours, not a lab up
            state_file(self.lab.name).unlink(missing_ok=True)
