"""The whole lab in one process, on a virtual (or scaled) clock: `lab simulate`, `lab up --in-process`.

`InProcessLab` builds every device of a lab file from the very command line a live lab starts its
process with (`runner.device_args` -> `emulator.build`), and runs them all on one asyncio loop
whose clock is virtual (`timed.vloop.VirtualTimeLoop`: it jumps from deadline to deadline, as fast
as the machine allows, deterministically) or scaled (`ScaledTimeLoop`: `speed` × the wall clock,
with real sockets beside). Nothing of a device is implemented twice: the devices take all time
from the loop, their TCP (Type II, the rails, control ports) runs on the memory network
(`transport.memory`) and their Type I links on virtual wires paced at the line rate. Between the
two ends of every link stands the tap a live lab puts there (`tap.wire.WireTap` for Type I,
`tap.tcp.TcpTap` for Type II, both on this loop), so a link takes the same tap commands.

It keeps `events.jsonl` (every device's events, in the loop's time: each link going up and down
among them, once a transition at each end, as that device logs it), a pcapng capture per link,
and a summary. Both files are flushed about every wall second (`FLUSH_EVERY`), so a run killed
outright leaves events and captures that end at about the same time; a run stopped early
(`interrupted`) says so in its summary. It is a `lab.access.LabAccess`.

With `invariants=True` (`lab simulate`) it runs the lab invariants throughout (`lab.safety.Watch`:
a look after every change an IXL, a trackside or the rails log) and its summary lists every
violation (`violations`, empty when none); `on_violation` hears each as it is found.

    lab = InProcessLab("reference", seed=1, out=Path("run"))
    lab.run(lambda lab: lab.sleep(3600))       # up, the coroutine, down; on a fresh loop
"""

from __future__ import annotations

import asyncio
import contextvars
import json
import logging
import secrets
import time
from collections.abc import Awaitable, Callable, Mapping
from functools import partial
from pathlib import Path
from typing import IO, Any, TypeVar

from ktcs_bench import kinds
from ktcs_bench.capture import CaptureWriter, open_writer
from ktcs_bench.emulator.build import build_device, device_namespace
from ktcs_bench.emulator.device import Device, Event
from ktcs_bench.errors import UsageError
from ktcs_bench.lab.invariants import Violation, ViolationJson
from ktcs_bench.lab.runner import device_args, lab_command, start_in_order
from ktcs_bench.lab.safety import Watch
from ktcs_bench.lab.state import read_state, state_file, write_state
from ktcs_bench.lab.topology import Lab, LinkSpec, load_lab, resolve_lab_path
from ktcs_bench.lab.view import LinkEntry
from ktcs_bench.messages import JsonObject, Message, ReadyInfo
from ktcs_bench.runtime import server_token, this_process
from ktcs_bench.tap.runner import Tap
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.tap.wire import WireTap
from ktcs_bench.timed.vloop import MAX_SPEED, ScaledTimeLoop, VirtualTimeLoop
from ktcs_bench.transport import jsonlines, memory, net
from ktcs_bench.transport.memory import VIRTUAL_SCHEME, MemoryNetwork

log = logging.getLogger("ktcs_bench.lab")
T = TypeVar("T")
CLOCKS = ("virtual", "scaled")
FLUSH_EVERY = 1.0
"""Wall seconds between flushes of events.jsonl and the captures during a run."""
WATCHED = frozenset({kinds.IXL, kinds.TRACKSIDE, kinds.TRACKCIRCUIT})
"""The devices whose every logged event is a change the invariants look at (`Watch.changed`)."""


class InProcessLab:
    """A lab file's devices, taps and links in this process (see the module docstring).

    `clock`: "virtual" (as fast as it goes) or "scaled" (`speed` × wall time, real sockets work).
    `seed`: the taps' fault injectors. `out`: where events.jsonl, captures/ and summary.json go
    (None: nothing is written). `console`: the CTC serves its web console (a scaled lab).
    `on_event`: called with each event of the lab's log (what it records, without a file)."""

    def __init__(
        self,
        lab_file: str | Path | Lab | None = None,
        *,
        clock: str = "virtual",
        seed: int = 0,
        out: Path | None = None,
        speed: float = 1.0,
        console: bool = False,
        token_file: Path | None = None,
        invariants: bool = False,
        on_violation: Callable[[Violation], None] | None = None,
        on_event: Callable[[dict[str, Any]], None] | None = None,
    ) -> None:
        if clock not in CLOCKS:
            raise UsageError(f"clock must be one of {', '.join(CLOCKS)}, not {clock!r}")
        if clock == "scaled" and not 0 < speed <= MAX_SPEED:
            raise UsageError(
                f"a lab in one process runs at most {MAX_SPEED:g}x real time (above that this "
                f"machine's devices cannot keep their links up), not {speed:g}x"
            )
        self.topology = (
            lab_file
            if isinstance(lab_file, Lab)
            else load_lab(resolve_lab_path(None if lab_file is None else str(lab_file)))
        )
        if "tls" in self.topology.type2_profile:
            raise UsageError(
                f"lab {self.topology.name}: Type II over TLS ({self.topology.type2_profile}) runs in a live "
                "lab only (lab up), not in one process"
            )
        external = [d.name for d in self.topology.devices.values() if d.external is not None]
        if external:
            raise UsageError(
                f"lab {self.topology.name}: external devices ({', '.join(external)}) are real "
                "ones a live lab links to (lab up); a lab in one process runs only its own"
            )
        self.clock, self.seed, self.out, self.speed = clock, seed, out, speed
        self.console = console
        # what the devices' ports require: the lab's token when it serves people (`token_file`:
        # its taps and control ports then listen on real sockets, see `serve`)
        self.token_file = token_file
        self.token = server_token(token_file)[0] if token_file else secrets.token_hex(32)
        self.net: MemoryNetwork | None = None
        self.objects: dict[str, Device] = {}  # the running device objects
        self.running: dict[str, list[asyncio.Task[None]]] = {}
        self.ready: dict[str, ReadyInfo] = {}  # what each device reported at its start
        self.endpoints: dict[str, dict[str, str]] = {}
        self.taps: dict[str, Tap] = {}
        self.crashed: dict[str, str] = {}
        self.notices: list[str] = []
        self.stop_requested = asyncio.Event()
        # why the run ended early (a signal's name), for the summary; None: it ran its course
        self.interrupted: str | None = None
        self.control_address = ""
        self.served: dict[str, str] = {}  # device -> the real address of its control port
        self._servers: list[net.Server] = []
        self._flushers: list[Callable[[], None]] = []  # the capture writers' (see `captures`)
        self._events: IO[str] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._t0 = 0.0
        self._wall0 = 0.0
        self._wall = 0.0
        self._virtual = 0.0
        self.invariants, self.on_violation = invariants, on_violation
        self.on_event = on_event  # each event as events.jsonl has it, written or not
        self.watch: Watch | None = None
        self._watching: asyncio.Task[None] | None = None

    # -- running it ---------------------------------------------------------------------------
    def new_loop(self) -> VirtualTimeLoop | ScaledTimeLoop:
        if self.clock == "virtual":
            return VirtualTimeLoop()
        return ScaledTimeLoop(self.speed)

    def _behind(self, late: float) -> None:
        """The scaled clock runs ahead of what this machine does (said once: `watch_behind`)."""
        log.warning(
            "lab %s: this machine does not keep up with the clock at %gx real time (a timer "
            "came %.1f s late on the lab's clock): links will time out and resync; a lower "
            "--speed keeps up (said once)", self.topology.name, self.speed, late,
        )  # fmt: skip

    def run(self, main: Callable[[InProcessLab], Awaitable[T]]) -> T:
        """Up, `await main(self)`, down -- on a fresh loop of this lab's clock. Between the loop's
        steps the files are flushed about every `FLUSH_EVERY` wall seconds."""
        loop = self.new_loop()
        if self.out is not None:
            loop.call_every_wall(FLUSH_EVERY, self.flush)
        try:
            return loop.run_until_complete(self._session(main))
        finally:
            memory.detach(loop)
            loop.close()

    async def _session(self, main: Callable[[InProcessLab], Awaitable[T]]) -> T:
        await self.up()
        try:
            return await main(self)
        finally:
            await self.down()

    # -- LabAccess -----------------------------------------------------------------------------
    @property
    def devices(self) -> dict[str, str]:
        return {n: d.kind for n, d in self.topology.devices.items()}

    @property
    def links(self) -> list[str]:
        return [lk.name for lk in self.topology.links]

    def now(self) -> float:
        return self._require_loop().time()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(seconds)

    async def device(self, name: str, obj: Message | Mapping[str, object]) -> dict[str, Any]:
        self._spec(name)
        device = self.objects.get(name)
        if device is None:
            return {"ok": False, "error": f"{name} is not running ({self._why_not(name)})"}
        if isinstance(obj, Message):  # as its port would have decoded it
            return _as_on_the_wire(await device._handle(obj, _NO_PEER))
        if not isinstance(obj, dict) or not isinstance(obj.get("cmd"), str):
            return {"ok": False, "error": 'a command is a JSON object {"cmd": ...}'}
        return _as_on_the_wire(await device._handle(dict(obj), _NO_PEER))

    async def link(self, name: str, obj: Mapping[str, object]) -> dict[str, Any]:
        spec = self._link(name)
        tap = self.taps.get(name)
        if tap is None:
            raise UsageError(f"link {name} has no tap (tap: false in the lab file)")
        if not isinstance(obj, dict):
            return {"ok": False, "error": 'a command is a JSON object {"cmd": ...}'}
        answer = tap.execute(obj)
        if answer.get("ok") and obj.get("cmd") != "status":
            self._note_lab(spec.name, "tap", str(answer.get("command", obj.get("cmd"))))
        return _as_on_the_wire(answer)

    async def lab(self, obj: Mapping[str, object]) -> dict[str, Any]:
        """The lab's commands as on a live lab's control port (`runner.lab_command`); `down`
        asks whoever runs the lab to stop it (`stop_requested`)."""
        if not isinstance(obj, dict):
            return {"ok": False, "error": 'a command is a JSON object {"cmd": ...}'}
        return _as_on_the_wire(await lab_command(self, obj))

    def captures(self) -> dict[str, Path]:
        """The capture files as they stand now (what the taps wrote is flushed onto them)."""
        if self.out is None:
            return {}
        self.flush()
        return {lk.name: self._capture_path(lk) for lk in self.topology.links if lk.tap}

    def flush(self) -> None:
        """What the run wrote so far onto its files: events.jsonl and every capture."""
        if self._events is not None:
            self._events.flush()
        for flush in self._flushers:
            flush()

    # -- start ---------------------------------------------------------------------------------
    async def up(self) -> None:
        """Start every device and tap in the live order (see `lab.runner`)."""
        loop = self._loop = asyncio.get_running_loop()
        self.net = memory.attach(loop)
        self.net.token = self.token
        self._t0, self._wall0 = loop.time(), time.monotonic()
        if self.out is not None:
            try:
                (self.out / "captures").mkdir(parents=True, exist_ok=True)
                self._events = (self.out / "events.jsonl").open("w", encoding="utf-8")
            except OSError as exc:
                raise UsageError(f"cannot write the run's output to {self.out}: {exc}") from None
        if self.invariants:
            self.watch = Watch(self, self.topology.load_line(), self.on_violation)
        await start_in_order(self.topology, self, self.endpoints)
        await self._trains_to_ctc()
        if self.watch is not None:
            self._watching = loop.create_task(self.watch.run())
        if isinstance(loop, ScaledTimeLoop):  # from here the clock should keep up (it is started)
            loop.watch_behind(self._behind)

    async def type2_end(self, link: LinkSpec, index: int, ctc: tuple[str, int]) -> str:
        if not link.tap:
            return f"tcp://{ctc[0]}:{ctc[1]}"
        host = self.topology.devices[link.a].host
        tap = TcpTap((host, 0), ctc, **self._tap_args(link, index))
        await self._open_tap(link, tap)
        assert tap.listen_address is not None
        return f"tcp://{tap.listen_address[0]}:{tap.listen_address[1]}"

    async def type1_ends(self, link: LinkSpec, index: int) -> tuple[str, str]:
        """Virtual wires, paced at the line rate, a tap between their ends (or none)."""
        assert self.net is not None
        if link.tap:
            await self._open_tap(link, WireTap(**self._tap_args(link, index)))
        else:
            self.net.join_serial(f"{link.name}/{link.a}", f"{link.name}/{link.b}")
        return f"{VIRTUAL_SCHEME}{link.name}/{link.a}", f"{VIRTUAL_SCHEME}{link.name}/{link.b}"

    def _tap_args(self, link: LinkSpec, index: int) -> dict[str, Any]:
        writers: list[CaptureWriter] = []
        if self.out is not None:
            writer = open_writer(str(self._capture_path(link)), link=link.type,
                                 flush_each=self.clock != "virtual")  # fmt: skip
            self._flushers.append(writer.flush)
            writers.append(writer)
        profile = (
            self.topology.type1_profile if link.type == "type1" else self.topology.type2_profile
        )
        return {"names": (link.a, link.b), "profile": profile, "name": link.name,
                "seed": self.seed * 1000 + index, "writers": writers, "epoch": False,
                "control": ("127.0.0.1", 0) if self.token_file else None,
                "token_file": self.token_file}  # fmt: skip

    async def _open_tap(self, link: LinkSpec, tap: Tap) -> None:
        await tap.open_here(announce=self.token_file is not None)
        self.taps[link.name] = tap

    def _capture_path(self, link: LinkSpec) -> Path:
        assert self.out is not None
        return self.out / "captures" / f"{link.name}.pcapng"

    def argv(self, name: str) -> list[str]:
        """The device's `ktcs-bench emulator` arguments: what a live lab starts it with, with the
        endpoints of this process (memory addresses, virtual wires)."""
        return device_args(self.topology, name, before=self.ready.get(name, {}),
                           endpoints=self.endpoints.get(name, {}), token_file=None,
                           console=self.console)  # fmt: skip

    async def _start(self, name: str) -> ReadyInfo:
        """Build the device from its command line and launch it as its own 'process': what it
        makes on the memory network is marked as its own (`memory.OWNER`)."""
        loop = self._require_loop()
        args = device_namespace(self.argv(name))
        device: Device = build_device(args, self.topology)
        device.clock = loop.time
        device.on_note = self._on_note  # its links' transitions too: the devices log them
        context = contextvars.copy_context()
        context.run(memory.OWNER.set, name)
        tasks = await loop.create_task(device.launch(self.token), context=context)
        self.objects[name] = device
        self.running[name] = tasks
        self.ready[name] = device.ready_info.copy()
        self.crashed.pop(name, None)
        for task in tasks:
            task.add_done_callback(partial(self._task_done, name, device))
        return device.ready_info

    async def _trains_to_ctc(self) -> None:
        """Tell a CTC that serves a console of every train (as `lab up` does)."""
        for ctc in self.topology.of_kind(kinds.CTC):
            device = self.objects.get(ctc.name)
            if device is None or not self.console:
                continue
            for d in self.topology.of_kind(kinds.TRAIN):
                train = str(d.options.get(kinds.TRAIN, d.name))
                await device.command({"cmd": "add_train", kinds.TRAIN: train,
                                      "control": self.ready[d.name]["control"]})  # fmt: skip

    # -- faults of devices -------------------------------------------------------------------------
    async def kill(self, name: str) -> None:
        """What the death of the device's process does: its connections are reset, its ports
        stop listening, its wires fall silent. `restart` brings it back."""
        self._spec(name)
        device = self.objects.pop(name, None)
        if device is None:
            raise UsageError(f"{name} is not running")
        assert self.net is not None
        self.net.drop(name)
        await device.end(self.running.pop(name, []))
        self._note_lab(name, "lab", "stopped")

    async def restart(self, name: str) -> None:
        """A fresh device object from the same command line at the same addresses (stopping the
        one that runs); its peers reconnect and resynchronise with it."""
        self._spec(name)
        if name in self.objects:
            await self.kill(name)
        await self._start(name)
        if self.topology.devices[name].kind == kinds.CTC:
            await self._trains_to_ctc()
        self.notices.append(f"{name} restarted")
        self._note_lab(name, "lab", "restarted")

    # -- looking ---------------------------------------------------------------------------------
    async def status(self) -> dict[str, Any]:
        devices = {
            n: (d.status() if (d := self.objects.get(n)) else None) for n in self.topology.devices
        }
        ctc = next(
            (s for n, s in devices.items() if self.topology.devices[n].kind == kinds.CTC and s),
            None,
        )
        return {
            "lab": self.topology.name,
            "clock": self.clock,
            "time": self.now(),
            "stations": (ctc or {}).get("stations", {}),
            "devices": {
                n: {"alive": n in self.objects, "crashed": self.crashed.get(n), "status": s}
                for n, s in devices.items()
            },
            "taps": {n: t.status() for n, t in self.taps.items()},
        }

    def link_map(self) -> list[LinkEntry]:
        out: list[LinkEntry] = []
        for link in self.topology.links:
            a_end = self.endpoints.get(link.a, {}).get(self.topology.peer_role(link, link.a), "")
            entry: LinkEntry = {"link": link.name, "type": link.type, "a": link.a, "b": link.b,
                                "a_end": a_end}  # fmt: skip
            tap = self.taps.get(link.name)
            if tap is not None and tap.control_address:
                entry["tap"] = f"{tap.control_address[0]}:{tap.control_address[1]}"
            if self.out is not None and link.tap:
                entry["capture"] = str(self._capture_path(link))
            out.append(entry)
        return out

    def summary(self) -> dict[str, Any]:
        """virtual_s, wall_s, speed_up, and each train: its status (arrivals if it reports them)."""
        virtual = (self.now() if self._loop is not None else self._virtual) - self._t0
        wall = (time.monotonic() - self._wall0) if self._loop is not None else self._wall
        trains = {}
        for d in self.topology.of_kind(kinds.TRAIN):
            device = self.objects.get(d.name)
            status = device.status() if device is not None else {}
            trains[d.name] = {k: status[k] for k in sorted(status) if k not in ("name", "kind")}
        return {
            "lab": self.topology.name,
            "seed": self.seed,
            "clock": self.clock,
            "virtual_s": round(virtual, 6),
            "wall_s": round(wall, 3),
            "speed_up": round(virtual / wall, 1) if wall > 0 else None,
            "trains": trains,
            "crashed": dict(sorted(self.crashed.items())),
            **({} if self.watch is None else {"violations": self.violations()}),
            # stopped early: by what, and at what time of the lab's clock (= virtual_s)
            "interrupted": None
            if self.interrupted is None
            else {"by": self.interrupted, "virtual_s": round(virtual, 6)},
        }

    def violations(self) -> list[ViolationJson]:
        """Every violation of the lab invariants found so far (none: not watched)."""
        if self.watch is None:
            return []
        return [{**v.to_json(), "time": round(v.time, 6)} for v in self.watch.reported]

    # -- stop --------------------------------------------------------------------------------------
    async def down(self) -> None:
        """Stop every device -- the IXLs first (as `lab down`), then the others in the reverse of
        their start, so the rails and the CTC go last -- then the taps; write the summary."""
        if self._loop is None:
            return
        if self._watching is not None:  # a last look at the lab as it ends
            self._watching.cancel()
            await asyncio.gather(self._watching, return_exceptions=True)
        if self.watch is not None:
            await self.watch.look()
            self.watch.closed = True  # the devices' stopping is no change of the line's state
        self._virtual, self._wall = self.now(), time.monotonic() - self._wall0
        summary = self.summary()
        ixls = [n for n in self.objects if self.topology.devices[n].kind == kinds.IXL]
        for name in [*ixls, *[n for n in reversed(self.objects) if n not in ixls]]:
            await self.kill(name)
        # the taps close their capture files as they go (each flushes its own); the loop's
        # periodic flush steps on while they do and must not reach a closed one
        self._flushers.clear()
        for tap in self.taps.values():
            await tap.close_here()
        self._unserve()
        if self._events is not None:
            self._events.close()
            self._events = None
        if self.out is not None:
            (self.out / "summary.json").write_text(
                json.dumps(summary, indent=2, sort_keys=True) + "\n", encoding="utf-8"
            )
        self._loop = None

    # -- served to people (lab up --in-process) ---------------------------------------------------
    async def serve(self) -> None:
        """Real sockets for people: the lab's control port and each device's (proxies to the
        objects), and the lab's state file, so `ktcs-bench lab status`, `ktcs-bench ctc ...`
        and the taps' words work as with a live lab. Needs a scaled clock."""
        if self.clock != "scaled" or self.token_file is None:
            raise UsageError("a lab serves people on the scaled clock with its token file")
        server = await jsonlines.serve(
            "127.0.0.1", 0, lambda obj, peer: self.lab(obj), token=self.token, real=True
        )
        self._servers.append(server)
        host, port = net.server_address(server)
        self.control_address = f"{host}:{port}"
        for name in self.topology.devices:
            await self._serve_device(name)
        self.write_state()

    async def _serve_device(self, name: str) -> None:
        async def handle(obj: JsonObject, peer: jsonlines.Peer) -> dict[str, Any]:
            return await self.device(name, obj)

        server = await jsonlines.serve("127.0.0.1", 0, handle, token=self.token, real=True)
        self._servers.append(server)
        host, port = net.server_address(server)
        self.served[name] = f"{host}:{port}"

    def write_state(self) -> None:
        devices = {}
        for name, spec in self.topology.devices.items():
            ready = {k: v for k, v in self.ready.get(name, {}).items() if k != "control"}
            devices[name] = {"pid": None, "kind": spec.kind, **ready,
                             "control": self.served.get(name, "")}  # fmt: skip
        write_state(self.topology.name, {
            "lab": self.topology.name, "file": str(self.topology.file), **this_process(),
            "control": self.control_address, "token_file": str(self.token_file),
            "in_process": {"clock": self.clock, "speed": self.speed},
            "devices": devices, "links": self.link_map(),
        })  # fmt: skip

    def _unserve(self) -> None:
        for server in self._servers:
            server.close()
        self._servers.clear()
        if self.control_address:
            state = read_state(self.topology.name) or {}
            if state.get("pid") == this_process()["pid"]:
                state_file(self.topology.name).unlink(missing_ok=True)

    # -- the event log -------------------------------------------------------------------------------
    def _log(self, event: dict[str, Any]) -> None:
        if self.on_event is not None:
            self.on_event(event)
        if self._events is not None:
            self._events.write(json.dumps(event, sort_keys=True, separators=(",", ":")) + "\n")

    def _on_note(self, device: Device, event: Event) -> None:
        self._log({"t": round(event["time"], 6), "device": device.name, "kind": event["kind"],
                   "text": event["text"]})  # fmt: skip
        if self.watch is not None and device.kind in WATCHED:
            self.watch.changed()

    def _note_lab(self, name: str, kind: str, text: str) -> None:
        self._log({"t": round(self.now(), 6), "device": name, "kind": kind, "text": text})
        if self.watch is not None:  # a fault on a link, a device restarted or stopped
            self.watch.changed()

    def _task_done(self, name: str, device: Device, task: asyncio.Task[None]) -> None:
        if task.cancelled() or self.objects.get(name) is not device:
            return
        exc = task.exception()
        if exc is not None:
            self.crashed[name] = f"{type(exc).__name__}: {exc}"
            self._note_lab(name, "crash", self.crashed[name])
            log.error("%s: %s", name, self.crashed[name])

    # -- internals ---------------------------------------------------------------------------------
    def _require_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise UsageError("the lab is not up")
        return self._loop

    def _spec(self, name: str) -> None:
        if name not in self.topology.devices:
            raise UsageError(
                f"no device {name!r} in lab {self.topology.name} ({', '.join(self.topology.devices)})"
            )

    def _link(self, name: str) -> LinkSpec:
        for link in self.topology.links:
            if link.name == name:
                return link
        raise UsageError(f"no link {name!r} in lab {self.topology.name} ({', '.join(self.links)})")

    def _why_not(self, name: str) -> str:
        return f"crashed: {self.crashed[name]}" if name in self.crashed else "stopped"


def _as_on_the_wire(answer: Mapping[str, object]) -> dict[str, Any]:
    """An answer as a control port's client reads it (JSON: lists, not tuples; string keys), so
    a procedure sees the same answer from a lab in one process as from a live one."""
    out: dict[str, Any] = json.loads(json.dumps(answer))
    return out


class _NoPeer:
    """A device command from the lab itself, not from a connection."""

    info: JsonObject = {}
    address = "in-process"


_NO_PEER: Any = _NoPeer()
