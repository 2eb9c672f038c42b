"""A tap on an asyncio loop and the wall clock: the `TapCore` bound to its ends and its control port.

`Tap` is what the adapters (pty.py, tcp.py) share. It runs an asyncio loop -- in a thread of its
own after `start()` (library use, tests, `lab up`), or in the caller's thread with `run()` (the
`ktcs-bench tap run` process) -- and does the I/O the core asks for: it hands deliveries to the
adapter, writes records to the capture writers, leaves the core's deadlines to the wall-clock
driver (`ktcs_bench.timed.aio.LoopTimer`; the core's clock is the loop's, set to epoch time when
the tap starts, since records carry epoch times), serves the control port and announces a named tap in the registry. The public methods are
thread-safe.

The control port (127.0.0.1, any free port unless told) is the JSON-lines server the devices'
control ports run (`ktcs_bench.transport.jsonlines`) -- the same token check included (the tap's
token: its lab's, given as `token_file`, else the user's) -- with the commands of `control.py`;
after the answer to `subscribe`, the connection carries the event stream, one JSON object a line.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Coroutine, Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, TypedDict, TypeVar

from ktcs_bench.capture import CaptureRecord, CaptureWriter
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.faults import Cut, Fault, FaultInjector
from ktcs_bench.messages import JsonObject
from ktcs_bench.runtime import server_token
from ktcs_bench.tap import registry
from ktcs_bench.tap.control import HELP, Command, parse_command
from ktcs_bench.tap.core import (
    HISTORY,
    CommandAnswer,
    CoreStatus,
    Subscription,
    TapCore,
    TapHeader,
    TapOutput,
)
from ktcs_bench.tap.registry import TapEnds, TapInfo
from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.transport import jsonlines, net

T = TypeVar("T")
START_TIMEOUT = 10.0


class TapStatus(TapInfo, CoreStatus):
    """A tap's status: its info and the core's (a kind of tap adds its own: `TcpStatus`,
    `PtyStatus`)."""


class TapStatusAnswer(TypedDict):
    ok: Literal[True]
    status: TapStatus


class TapHelpAnswer(TypedDict):
    ok: Literal[True]
    help: str


class TapRefused(TypedDict):
    """`{"ok": false, "error": ...}`: not done, and why (the shape of every port's error,
    `messages.Refused`)."""

    ok: Literal[False]
    error: str


class TapSubscribeAnswer(TapHeader):
    """`{"ok": true, ...}` and the stream's header."""

    ok: Literal[True]


TapAnswer = CommandAnswer | TapStatusAnswer | TapHelpAnswer | TapRefused
"""A tap control port's answer to a command (`subscribe` is answered by `TapSubscribeAnswer`)."""


class Tap:
    """The common part of every tap: the core, its clock and timer, writers, control port, life."""

    kind = "tap"

    def __init__(
        self,
        *,
        names: tuple[str, str] = ("a", "b"),
        profile: str | FrameProfile = "ktcs-type1",
        seed: int = 0,
        control: tuple[str, int] | None = ("127.0.0.1", 0),
        name: str | None = None,
        writers: Iterable[CaptureWriter] = (),
        history: int = HISTORY,
        token_file: str | Path | None = None,
        epoch: bool = True,
    ) -> None:
        self.profile = get_profile(profile) if isinstance(profile, str) else profile
        self.core = TapCore(names, self.profile, seed=seed, history=history)
        self.names = self.core.names
        self.directions = self.core.directions
        self.name = name
        self._control_want = control
        self.control_address: tuple[str, int] | None = None
        # the token its control port requires (runtime.server_token; the user's by default)
        self._token, self.token_file = server_token(token_file)
        self._writers = list(writers)
        self.epoch = epoch  # records in epoch time (live); else in the loop's (a virtual lab)
        self._wakes: dict[Subscription, asyncio.Event] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop_event: asyncio.Event | None = None
        self.timer = LoopTimer(self.core, lambda now, out: self._apply(out))
        self._tasks: set[asyncio.Task[Any]] = set()
        self._server: net.Server | None = None
        self._real_control = False  # the control port on a real socket even on a memory network
        self._announced = False
        self._closing = False

    # -- life cycle --------------------------------------------------------------------------
    def start(self) -> Tap:
        """Run the tap in a background thread; returns once its ends and control port are up."""
        if self._thread is not None:
            raise UsageError("tap already started")
        self._thread = threading.Thread(
            target=self._thread_main, name=f"tap-{self.name}", daemon=True
        )
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            raise PeerError("tap did not start in time")
        if self._error is not None:
            self._thread.join()
            self._thread = None
            raise self._error
        return self

    def run(self, on_ready: Callable[[Tap], None] | None = None) -> None:
        """Run in this thread until `stop()`, SIGINT or SIGTERM."""
        asyncio.run(self._main(on_ready, signals=True))
        if self._error is not None:
            raise self._error

    def stop(self) -> None:
        loop, stop = self._loop, self._stop_event
        if loop is not None and stop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(stop.set)
        if self._thread is not None and threading.current_thread() is not self._thread:
            self._thread.join(10)
            self._thread = None

    def __enter__(self) -> Tap:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _thread_main(self) -> None:
        try:
            asyncio.run(self._main(None, signals=False))
        except BaseException as exc:  # reported to start()
            self._error = self._error or exc
            self._ready.set()

    async def open_here(self, *, announce: bool = False) -> None:
        """Run the tap on the running loop, with no thread of its own (a lab in one process);
        `close_here()` ends it. `announce`: its control port is a real socket (whatever network
        the loop has) and a named tap announces itself, so `ktcs-bench tap ...` finds it."""
        self._real_control = announce
        if not await self._open():
            assert self._error is not None
            raise self._error
        if announce and self.name:
            registry.announce(self.name, self.info())
            self._announced = True
        self._ready.set()

    async def close_here(self) -> None:
        if self._announced and self.name:
            registry.withdraw(self.name)
        await self._shut(own_loop=False)

    async def _open(self) -> bool:
        """Open the ends and the control port on the running loop; False (and `_error`) if not."""
        loop = asyncio.get_running_loop()
        self._loop = loop
        # the core's `now`: epoch time (monotonic) live; the loop's own time in a virtual lab
        self.timer.origin = loop.time() - time.time() if self.epoch else 0.0
        self._loop_thread = threading.get_ident()
        self._stop_event = asyncio.Event()
        self._server = None
        try:
            await self._open_ends()
            if self._control_want is not None:
                self._server = await jsonlines.serve(
                    *self._control_want, self._handle, token=self._token, real=self._real_control
                )
                self.control_address = net.server_address(self._server)
        except OSError as exc:
            self._error = PeerError(f"tap cannot open its ends: {exc}")
            return False
        return True

    async def _main(self, on_ready: Callable[[Tap], None] | None, signals: bool) -> None:
        loop = asyncio.get_running_loop()
        try:
            if not await self._open():
                self._ready.set()
                return
            assert self._stop_event is not None
            if signals:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.add_signal_handler(sig, self._stop_event.set)
            if self.name:
                registry.announce(self.name, self.info())
            self._ready.set()
            if on_ready is not None:
                on_ready(self)
            await self._stop_event.wait()
        finally:
            if self.name and self._ready.is_set() and self._error is None:
                registry.withdraw(self.name)
            await self._shut(own_loop=True)

    async def _shut(self, own_loop: bool) -> None:
        self._closing = True
        if self._server is not None:
            self._server.close()
        self.timer.cancel()
        for wake in self._wakes.values():
            wake.set()  # subscribers see the tap closing and end their streams
        if own_loop:  # everything else on this loop is the tap's: connections, readers, subscribers
            others = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        else:
            others = sorted(self._tasks, key=lambda t: t.get_name())
        for task in others:
            task.cancel()
        await asyncio.gather(*others, return_exceptions=True)
        await self._close_ends()
        self._apply(self.core.close())
        for w in self._writers:
            w.close()
        self._loop = None

    def _spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """A task of the tap's (held here: the loop keeps only a weak reference)."""
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # -- to be provided by a kind of tap -----------------------------------------------------
    async def _open_ends(self) -> None:
        raise NotImplementedError

    async def _close_ends(self) -> None:
        raise NotImplementedError

    def _deliver(self, direction: str, data: bytes) -> None:
        raise NotImplementedError

    def _ends_info(self) -> TapEnds:
        """Where its ends are, as its info says (each kind of tap its own keys)."""
        return {}

    def _link_cut(self) -> None:
        """`cut` with no direction: the kind of tap may do more than drop bytes (TCP closes)."""

    def _status(self) -> TapStatus:
        return {**self.info(), **self.core.status()}

    # -- public, thread-safe API -------------------------------------------------------------
    @property
    def injectors(self) -> dict[str, FaultInjector]:
        """The fault injector of each direction (read them in the tap's thread or once stopped)."""
        return self.core.injectors

    def info(self) -> TapInfo:
        """What a user needs to reach this tap (printed by `tap run`, announced by name)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "profile": self.profile.name,
            "protocol": self.profile.protocol,
            "names": list(self.names),
            "control": list(self.control_address) if self.control_address else None,
            "token_file": str(self.token_file),
            "pid": os.getpid(),
            **self._ends_info(),
        }

    def inject(self, fault: Fault) -> None:
        self._call(self._command, Command(fault.verb, fault.direction, fault))

    def cut(self, direction: str | None = None) -> None:
        self.inject(Cut(direction=direction))

    def restore(self, direction: str | None = None) -> None:
        self._call(self._command, Command("restore", direction))

    def clear(self) -> None:
        self._call(self._command, Command("clear"))

    def send(self, direction: str, data: bytes) -> None:
        """Inject bytes as if the sender of `direction` ("a>b") had written them."""
        self._call(self._command, Command("send", direction, data=data))

    def status(self) -> TapStatus:
        return self._call(self._status)

    def execute(self, command: str | Mapping[str, object]) -> TapAnswer:
        """One control command, as words (`ber 1e-3 a>b`) or JSON; its JSON answer."""
        try:
            if isinstance(command, str):
                cmd = parse_command(command, self.names)
            else:
                cmd = Command.from_json(command)
        except UsageError as exc:
            return {"ok": False, "error": str(exc)}
        return self._call(self._answer, cmd)

    def records(self) -> list[CaptureRecord]:
        """The recorded traffic so far (the last HISTORY records)."""
        if self._loop is None:
            return list(self.core.history)
        return self._call(lambda: list(self.core.history))

    def add_writer(self, writer: CaptureWriter) -> None:
        self._call(self._writers.append, writer)

    def _call(self, fn: Callable[..., T], *args: Any) -> T:
        loop = self._loop
        if loop is None:
            raise UsageError("the tap is not running")
        if threading.get_ident() == self._loop_thread:
            return fn(*args)
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()

        def call() -> None:
            try:
                fut.set_result(fn(*args))
            except BaseException as exc:
                fut.set_exception(exc)

        loop.call_soon_threadsafe(call)
        return fut.result(timeout=10)

    # -- inside the loop ---------------------------------------------------------------------
    def _now(self) -> float:
        """Records carry epoch times (captures, monitors on other machines)."""
        return self.timer.now()

    def _command(self, cmd: Command) -> CommandAnswer:
        answer, out = self.core.execute(cmd, self._now())
        self._apply(out)
        return answer

    def _answer(self, cmd: Command) -> TapAnswer:
        """A control command's JSON answer (never raises for a bad command)."""
        try:
            if cmd.verb == "status":
                return {"ok": True, "status": self._status()}
            if cmd.verb == "help":
                return {"ok": True, "help": HELP}
            if cmd.verb == "subscribe":
                return {"ok": False, "error": "subscribe works on the control port only"}
            return self._command(cmd)
        except UsageError as exc:
            return {"ok": False, "error": str(exc)}

    def _on_data(self, direction: str, data: bytes) -> None:
        self._apply(self.core.receive(direction, data, self._now()))

    def _apply(self, out: TapOutput) -> None:
        """Do what the core asked for, then wait for its next deadline."""
        for direction, data in out.deliveries:
            self._deliver(direction, data)
        for r in out.records:
            for w in self._writers:
                w.write(r)
        if out.link_cut:
            self._link_cut()
        if out.events:
            for wake in self._wakes.values():
                wake.set()
        if not self._closing:
            self.timer.poke()

    # -- the control port ------------------------------------------------------------------------
    async def _handle(self, obj: JsonObject, peer: jsonlines.Peer) -> TapAnswer | None:
        try:
            cmd = Command.from_json(obj)
        except KtcsError as exc:
            return {"ok": False, "error": str(exc)}
        if cmd.verb == "subscribe":
            await self._stream(cmd.history, peer)
            return None
        return self._answer(cmd)

    async def _stream(self, history: bool, peer: jsonlines.Peer) -> None:
        """Answer `subscribe`, then send every event until the subscriber or the tap goes."""
        sub = self.core.subscribe(history)
        wake = self._wakes[sub] = asyncio.Event()
        header: TapSubscribeAnswer = {"ok": True, "profile": self.profile.name,
                                   "protocol": self.profile.protocol, "names": list(self.names),
                                   "tap": self.name, "kind": self.kind}  # fmt: skip
        peer.send(header)
        gone = asyncio.ensure_future(self._until_eof(peer.reader))
        try:
            while not self._closing:
                for event in sub.take():
                    peer.send(event)
                await peer.writer.drain()
                woken = asyncio.ensure_future(wake.wait())
                done, _ = await asyncio.wait({woken, gone}, return_when=asyncio.FIRST_COMPLETED)
                woken.cancel()
                if gone in done:
                    return
                wake.clear()
        finally:
            gone.cancel()
            self.core.unsubscribe(sub)
            del self._wakes[sub]
            if self._closing:
                peer.close()

    @staticmethod
    async def _until_eof(reader: asyncio.StreamReader) -> None:
        """A subscriber sends nothing more; what it does send is read and dropped."""
        with contextlib.suppress(ConnectionError, OSError):
            while await reader.read(65536):
                pass
