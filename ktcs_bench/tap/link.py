"""Taps: proxies between the two ends of a link that record both directions and inject faults.

`PtyTap` creates two pty pairs; device a opens `paths["a"]`, device b opens `paths["b"]`, and the
tap shuttles bytes between the masters. `TcpTap` listens on one address and, for each connection,
connects to the target (one connection at a time: a new one replaces the old). Both run an asyncio
loop -- in a thread of their own after `start()` (library use, tests), or in the caller's thread
with `run()` (the `ktcs-bench tap run` process). The public methods are thread-safe.

The logic is elsewhere and sans-I/O: `FaultInjector` (`ktcs_bench.faults`) per direction, `Recorder`
(recorder.py) for timestamped frames, `parse_command` (control.py) for the control language. The
control port (127.0.0.1, line-based) serves the same commands to other processes, and `subscribe`
streams the recorded traffic as JSON lines.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import logging
import os
import random
import signal
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar

from ktcs_bench.capture.records import CaptureRecord
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.faults import Cut, Fault, FaultInjector
from ktcs_bench.runtime import server_token, token_matches
from ktcs_bench.tap import registry
from ktcs_bench.tap.control import HELP, Command, parse_command, refusal, token_given
from ktcs_bench.tap.recorder import Recorder
from ktcs_bench.transport.tcp import open_tcp

log = logging.getLogger("ktcs_bench.tap")

T = TypeVar("T")
HISTORY = 10_000  # records kept for `records()` and `subscribe history`
SUBSCRIBER_QUEUE = 10_000  # events buffered per slow subscriber before it misses some
PTY_PENDING_MAX = 1 << 20  # bytes queued for a pty nobody reads before the oldest are dropped
START_TIMEOUT = 10.0


class RecordWriter(Protocol):
    def write(self, record: CaptureRecord) -> None: ...

    def close(self) -> None: ...


def record_event(record: CaptureRecord) -> dict[str, Any]:
    return {"time": record.time, "direction": record.direction, "hex": record.data.hex()}


class Tap:
    """The common part of every tap: faults, recording, control port, life cycle."""

    kind = "tap"

    def __init__(
        self,
        *,
        names: tuple[str, str] = ("a", "b"),
        profile: str | FrameProfile = "ktcs-type1",
        seed: int = 0,
        control: tuple[str, int] | None = ("127.0.0.1", 0),
        name: str | None = None,
        writers: Iterable[RecordWriter] = (),
        history: int = HISTORY,
        token_file: str | Path | None = None,
    ) -> None:
        a, b = names
        if a == b or ">" in a + b or a.endswith("-") or b.endswith("-"):
            raise UsageError(f"tap end names must differ and contain no '>': {names}")
        self.names = (a, b)
        self.profile = get_profile(profile) if isinstance(profile, str) else profile
        self.name = name
        self.directions = (f"{a}>{b}", f"{b}>{a}")
        rng = random.Random(seed)
        self.injectors = {
            d: FaultInjector(self.profile, random.Random(rng.getrandbits(64)))
            for d in self.directions
        }
        self.recorder = Recorder(self.profile)
        self._control_want = control
        self.control_address: tuple[str, int] | None = None
        # the token its control port requires (runtime.server_token; the user's by default)
        self._token, self.token_file = server_token(token_file)
        self._writers = list(writers)
        self._history: deque[CaptureRecord] = deque(maxlen=history)
        self._history_lock = threading.Lock()
        self._callbacks: list[Callable[[dict[str, Any]], None]] = []
        self._queues: set[asyncio.Queue[dict[str, Any] | None]] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop_event: asyncio.Event | None = None
        self._wake: asyncio.Event | None = None
        self._cut_all = False
        self._tasks: set[asyncio.Task[Any]] = set()

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

    async def _main(self, on_ready: Callable[[Tap], None] | None, signals: bool) -> None:
        loop = asyncio.get_running_loop()
        self._loop = loop
        self._loop_thread = threading.get_ident()
        self._stop_event = asyncio.Event()
        self._wake = asyncio.Event()
        server: asyncio.Server | None = None
        try:
            try:
                await self._open_ends()
                if self._control_want is not None:
                    server = await asyncio.start_server(self._control_client, *self._control_want)
                    sockname = server.sockets[0].getsockname()
                    self.control_address = (str(sockname[0]), int(sockname[1]))
            except OSError as exc:
                self._error = PeerError(f"tap cannot open its ends: {exc}")
                self._ready.set()
                return
            if signals:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.add_signal_handler(sig, self._stop_event.set)
            if self.name:
                registry.announce(self.name, self.info())
            self._spawn(self._housekeeper())
            self._ready.set()
            if on_ready is not None:
                on_ready(self)
            await self._stop_event.wait()
        finally:
            if self.name and self._ready.is_set() and self._error is None:
                registry.withdraw(self.name)
            if server is not None:
                server.close()
            for q in list(self._queues):
                q.put_nowait(None)
            for task in list(self._tasks):
                task.cancel()
            if self._tasks:
                await asyncio.gather(*self._tasks, return_exceptions=True)
            await self._close_ends()
            if server is not None:
                await server.wait_closed()
            self._publish_records(self.recorder.flush())
            for w in self._writers:
                w.close()
            self._loop = None

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task: asyncio.Task[Any] = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- to be provided by a kind of tap -----------------------------------------------------
    async def _open_ends(self) -> None:
        raise NotImplementedError

    async def _close_ends(self) -> None:
        raise NotImplementedError

    def _deliver(self, direction: str, data: bytes) -> None:
        raise NotImplementedError

    def _ends_info(self) -> dict[str, Any]:
        return {}

    def _cut_everything(self) -> None:
        """`cut` with no direction: the kind of tap may do more than drop bytes (TCP closes)."""

    # -- public, thread-safe API -------------------------------------------------------------
    def info(self) -> dict[str, Any]:
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
        self._call(self._apply, fault)

    def cut(self, direction: str | None = None) -> None:
        self.inject(Cut(direction=direction))

    def restore(self, direction: str | None = None) -> None:
        self.execute(f"restore {direction or 'both'}")

    def clear(self) -> None:
        self.execute("clear")

    def send(self, direction: str, data: bytes) -> None:
        """Inject bytes as if the sender of `direction` ("a>b") had written them."""
        self.execute(f"send {direction} {data.hex()}")

    def status(self) -> dict[str, Any]:
        return self._call(self._status)

    def execute(self, line: str) -> str:
        """Run one control command (see control.py); returns the reply line."""
        return self._call(self._execute_line, line)

    def records(self) -> list[CaptureRecord]:
        """The recorded traffic so far (the last HISTORY records)."""
        with self._history_lock:
            return list(self._history)

    def add_writer(self, writer: RecordWriter) -> None:
        self._call(self._writers.append, writer)

    def on_event(self, callback: Callable[[dict[str, Any]], None]) -> None:
        """Call `callback(event)` (in the tap's thread) for every record and fault event."""
        self._call(self._callbacks.append, callback)

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
    def _targets(self, direction: str | None) -> list[str]:
        return list(self.directions) if direction is None else [direction]

    def _apply(self, fault: Fault) -> None:
        now = time.time()
        if fault.direction is not None and fault.direction not in self.directions:
            raise UsageError(f"this tap has directions {', '.join(self.directions)}")
        for d in self._targets(fault.direction):
            self.injectors[d].apply(fault, now)
        if isinstance(fault, Cut) and fault.direction is None:
            self._cut_all = True
            self._cut_everything()
        self._emit({"time": now, "event": "fault", "command": fault.command()})
        self._pump(now)

    def _execute_line(self, line: str) -> str:
        try:
            cmd = parse_command(line, self.names)
            return self._execute(cmd)
        except UsageError as exc:
            return f"error {exc}"

    def _execute(self, cmd: Command) -> str:
        now = time.time()
        if cmd.verb == "help":
            return "ok " + " | ".join(x.strip() for x in HELP.splitlines() if x.strip())
        if cmd.verb == "status":
            return "ok " + json.dumps(self._status())
        if cmd.verb == "subscribe":
            return "error subscribe works on the control port only"
        if cmd.verb == "clear":
            for inj in self.injectors.values():
                inj.clear(now)
            self._cut_all = False
            self._emit({"time": now, "event": "fault", "command": "clear"})
        elif cmd.verb == "restore":
            for d in self._targets(cmd.direction):
                self.injectors[d].restore()
            if cmd.direction is None:
                self._cut_all = False
            self._emit({"time": now, "event": "fault", "command": "restore"})
        elif cmd.verb == "send":
            assert cmd.direction is not None
            self.injectors[cmd.direction].feed(cmd.data, now)
            self._emit({"time": now, "event": "send", "command": f"send {cmd.direction} "
                        f"{cmd.data.hex()}"})  # fmt: skip
        elif cmd.fault is not None:
            self._apply(cmd.fault)
            return f"ok {cmd.fault.command()}"
        self._pump(now)
        return f"ok {cmd.verb}"

    def _status(self) -> dict[str, Any]:
        return {
            **self.info(),
            "cut": self._cut_all,
            "records": len(self._history),
            "directions": {d: inj.describe() for d, inj in self.injectors.items()},
        }

    def _on_data(self, direction: str, data: bytes) -> None:
        now = time.time()
        self.injectors[direction].feed(data, now)
        self._pump(now)

    def _pump(self, now: float) -> None:
        for d, inj in self.injectors.items():
            out = inj.poll(now)
            if out:
                self._deliver(d, out)
                self._publish_records(self.recorder.feed(d, out, now))
        self._publish_records(self.recorder.poll(now))
        if self._wake is not None:
            self._wake.set()

    def _publish_records(self, records: list[CaptureRecord]) -> None:
        for r in records:
            with self._history_lock:
                self._history.append(r)
            for w in self._writers:
                w.write(r)
            self._emit(record_event(r))

    def _emit(self, event: dict[str, Any]) -> None:
        for cb in self._callbacks:
            cb(event)
        for q in self._queues:
            if q.qsize() < SUBSCRIBER_QUEUE:
                q.put_nowait(event)

    async def _housekeeper(self) -> None:
        assert self._wake is not None
        while True:
            self._pump(time.time())
            deadlines = [inj.next_deadline() for inj in self.injectors.values()]
            deadlines.append(self.recorder.next_deadline())
            pending = [t for t in deadlines if t is not None]
            timeout = None if not pending else max(0.0, min(pending) - time.time()) + 0.001
            self._wake.clear()
            # asyncio.timeout, not wait_for: on 3.11 wait_for can swallow a cancellation that
            # races with the wake-up, and this loop would then outlive stop()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(timeout):
                    await self._wake.wait()

    async def _control_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        admitted = False
        try:
            while True:
                line = await reader.readline()
                if not line:
                    break
                text = line.decode("utf-8", errors="replace").strip()
                if not text:
                    continue
                given = token_given(text)
                if given is not None or not admitted:
                    admitted = given is not None and token_matches(given, self._token)
                    reply = "ok" if admitted else refusal(given)
                    if not admitted:
                        peer = writer.get_extra_info("peername")
                        log.warning("tap %s: %s from %s", self.name or "", reply, peer)
                elif text.split()[0].lower() == "subscribe":
                    await self._serve_subscriber(text, reader, writer)
                    break
                else:
                    reply = self._execute_line(text)
                writer.write((reply + "\n").encode())
                await writer.drain()
        except (ConnectionError, OSError, asyncio.CancelledError):
            pass
        finally:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()

    async def _serve_subscriber(
        self, text: str, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        try:
            cmd = parse_command(text, self.names)
        except UsageError as exc:
            writer.write(f"error {exc}\n".encode())
            return
        queue: asyncio.Queue[dict[str, Any] | None] = asyncio.Queue()
        header = {"profile": self.profile.name, "protocol": self.profile.protocol,
                  "names": list(self.names), "tap": self.name, "kind": self.kind}  # fmt: skip
        writer.write(("ok " + json.dumps(header) + "\n").encode())
        if cmd.history:
            for r in self.records():
                queue.put_nowait(record_event(r))
        self._queues.add(queue)
        eof = asyncio.ensure_future(reader.read())
        try:
            while True:
                get = asyncio.ensure_future(queue.get())
                done, _ = await asyncio.wait({get, eof}, return_when=asyncio.FIRST_COMPLETED)
                if get not in done:
                    get.cancel()
                    return
                event = get.result()
                if event is None:
                    return
                writer.write((json.dumps(event) + "\n").encode())
                await writer.drain()
        finally:
            eof.cancel()
            self._queues.discard(queue)


@dataclass
class _Pty:
    master: int
    slave: int
    path: str
    pending: bytearray = field(default_factory=bytearray)
    writing: bool = False
    dropped: int = 0


class PtyTap(Tap):
    """A tap between two ptys: device a opens `paths[a]`, device b opens `paths[b]`.

    with PtyTap(names=("ixl", "atc")) as tap:
        ixl = serial.Serial(tap.paths["ixl"]); atc = serial.Serial(tap.paths["atc"])
    """

    kind = "pty"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._ptys: dict[str, _Pty] = {}
        # open the ptys now, so `paths` is known before start()
        try:
            for end in self.names:
                master, slave = os.openpty()
                tty.setraw(slave)
                os.set_blocking(master, False)
                self._ptys[end] = _Pty(master, slave, os.ttyname(slave))
        except OSError as exc:
            self._close_fds()
            raise PeerError(f"cannot create a pty: {exc}") from None

    @property
    def paths(self) -> dict[str, str]:
        return {end: p.path for end, p in self._ptys.items()}

    def _ends_info(self) -> dict[str, Any]:
        return {"paths": self.paths}

    def _other(self, end: str) -> str:
        return self.names[1] if end == self.names[0] else self.names[0]

    async def _open_ends(self) -> None:
        loop = asyncio.get_running_loop()
        for end, p in self._ptys.items():
            loop.add_reader(p.master, self._readable, end)

    def _readable(self, end: str) -> None:
        p = self._ptys[end]
        try:
            data = os.read(p.master, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: no slave open (cannot happen while we hold one), be quiet
            return
        if data:
            self._on_data(f"{end}>{self._other(end)}", data)

    def _deliver(self, direction: str, data: bytes) -> None:
        end = direction.split(">", 1)[1]
        p = self._ptys[end]
        p.pending += data
        if len(p.pending) > PTY_PENDING_MAX:
            extra = len(p.pending) - PTY_PENDING_MAX
            del p.pending[:extra]
            p.dropped += extra
        self._flush(end)

    def _flush(self, end: str) -> None:
        p = self._ptys[end]
        loop = asyncio.get_running_loop()
        while p.pending:
            try:
                n = os.write(p.master, p.pending)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                p.dropped += len(p.pending)
                p.pending.clear()
                break
            if n == 0:
                if not p.writing:
                    loop.add_writer(p.master, self._flush, end)
                    p.writing = True
                return
            del p.pending[:n]
        if p.writing:
            loop.remove_writer(p.master)
            p.writing = False

    async def _close_ends(self) -> None:
        loop = asyncio.get_running_loop()
        for p in self._ptys.values():
            loop.remove_reader(p.master)
            if p.writing:
                loop.remove_writer(p.master)
        self._close_fds()

    def _close_fds(self) -> None:
        for p in self._ptys.values():
            for fd in (p.master, p.slave):
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._ptys.clear()

    def __del__(self) -> None:
        if self._ptys and self._loop is None and self._thread is None:
            self._close_fds()


@dataclass
class _Conn:
    a_reader: asyncio.StreamReader
    a_writer: asyncio.StreamWriter
    b_reader: asyncio.StreamReader
    b_writer: asyncio.StreamWriter
    peer: tuple[str, int]


class TcpTap(Tap):
    """A tap between TCP ends: end a connects to `listen`, the tap connects on to `target` (end b).

        with TcpTap(("127.0.0.1", 0), ("127.0.0.1", 5020), names=("ixl", "ctc")) as tap:
            ixl connects to tap.listen_address
    One connection at a time: a new connection replaces the old one. `cut()` closes both sides
    and refuses connections until `restore()`.
    """

    kind = "tcp"

    def __init__(self, listen: tuple[str, int], target: tuple[str, int], **kwargs: Any) -> None:
        kwargs.setdefault("profile", "ktcs-type2")
        super().__init__(**kwargs)
        self.listen = listen
        self.target = target
        self.listen_address: tuple[str, int] | None = None
        self._server: asyncio.Server | None = None
        self._conn: _Conn | None = None
        self.connections = 0

    def _ends_info(self) -> dict[str, Any]:
        addr = self.listen_address or self.listen
        return {"listen": list(addr), "target": list(self.target)}

    @property
    def connected(self) -> bool:
        return self._conn is not None

    async def _open_ends(self) -> None:
        self._server = await asyncio.start_server(self._accept, *self.listen)
        sockname = self._server.sockets[0].getsockname()
        self.listen_address = (str(sockname[0]), int(sockname[1]))

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername") or ("?", 0)
        if self._cut_all:
            writer.close()
            self._emit({"time": time.time(), "event": "refused", "peer": list(peer[:2])})
            return
        try:
            b_reader, b_writer = await asyncio.wait_for(open_tcp(*self.target), 5)
        except (OSError, TimeoutError) as exc:
            writer.close()
            self._emit({"time": time.time(), "event": "target-failed", "error": str(exc)})
            return
        if self._conn is not None:
            self._drop("replaced by a new connection")
        self._publish_records(self.recorder.flush())
        conn = _Conn(reader, writer, b_reader, b_writer, (str(peer[0]), int(peer[1])))
        self._conn = conn
        self.connections += 1
        a, b = self.names
        for w in self._writers:
            set_endpoint = getattr(w, "set_endpoint", None)
            if set_endpoint is not None:
                set_endpoint(a, *conn.peer)
                set_endpoint(b, *self.target)
        self._emit({"time": time.time(), "event": "connected", "peer": list(conn.peer)})
        self._spawn(self._read(conn, reader, self.directions[0]))
        self._spawn(self._read(conn, b_reader, self.directions[1]))

    async def _read(self, conn: _Conn, reader: asyncio.StreamReader, direction: str) -> None:
        try:
            while True:
                data = await reader.read(65536)
                if not data or conn is not self._conn:
                    break
                self._on_data(direction, data)
        except (ConnectionError, OSError):
            pass
        finally:
            if conn is self._conn:
                self._drop(f"{direction.split('>')[0]} closed")

    def _deliver(self, direction: str, data: bytes) -> None:
        conn = self._conn
        if conn is None:
            return
        w = conn.b_writer if direction == self.directions[0] else conn.a_writer
        if not w.is_closing():
            w.write(data)

    def _drop(self, reason: str) -> None:
        conn, self._conn = self._conn, None
        if conn is None:
            return
        for inj in self.injectors.values():  # nothing of this connection reaches the next one
            inj.discard()
        for w in (conn.a_writer, conn.b_writer):
            with contextlib.suppress(Exception):
                w.close()
        self._emit({"time": time.time(), "event": "disconnected", "reason": reason})

    def _cut_everything(self) -> None:
        self._drop("cut")

    def _status(self) -> dict[str, Any]:
        return {**super()._status(), "connected": self.connected,
                "connections": self.connections}  # fmt: skip

    async def _close_ends(self) -> None:
        self._drop("tap stopped")
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
