"""What every emulator process shares: the loop clock, the wall-clock driver of its sans-I/O
core's deadlines (`drive`: `ktcs_bench.timed.aio.LoopTimer`), an event log, a JSON-lines control
port, and the "ready" line a launcher reads.

A device prints exactly one JSON line on stdout when it is up: {"ready": NAME, "kind": KIND,
"control": "HOST:PORT", "ptys": {PEER: PATH}, ...}, or {"error": TEXT} when it cannot start (a
port taken); everything else goes to stderr (logging). Given a lifeline (the read end of a pipe
its launcher holds the other end of), it stops when the launcher is gone.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any, ClassVar, TypedDict

from ktcs_bench import kinds
from ktcs_bench.binding import LinkBinding
from ktcs_bench.emulator.code_link import CodePort
from ktcs_bench.emulator.rails import Hello, RailsClient
from ktcs_bench.messages import (
    DEVICE,
    Answer,
    BadMessage,
    Events,
    EventsAnswer,
    JsonObject,
    Message,
    ReadyInfo,
    ReadyLine,
    Refused,
    Status,
    StatusAnswer,
    Stop,
    answer,
    decode,
)
from ktcs_bench.runtime import server_token
from ktcs_bench.station.model import Line, StationView
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.timed import Out, Sink, Timed
from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.transport import jsonlines, net
from ktcs_bench.transport.endpoints import Endpoint
from ktcs_bench.type1 import LinkConfig

log = logging.getLogger("ktcs_bench.emulator")


class Event(TypedDict):
    """One event a device noted (its `events` command answers the last of them)."""

    time: float  # on the device's clock (wall time live, the loop's in a lab in one process)
    kind: str  # e.g. control, link, fault, ars
    text: str


class Device:
    kind = "device"
    messages: ClassVar[object] = DEVICE  # the commands its control port takes (a union)

    def __init__(self, name: str, control: tuple[str, int] = ("127.0.0.1", 0)) -> None:
        self.name = name
        self.control_address = control
        self.events: deque[Event] = deque(maxlen=2000)
        self.timer: LoopTimer[Any] | None = None  # the device's core on the wall clock
        self._stop: asyncio.Event | None = None
        self._server: net.Server | None = None
        self.ready_info: ReadyInfo = {}
        self.lifeline: int | None = None  # fd: end of file there means the launcher is gone
        self.token_file: str | None = None  # the token its control port requires (runtime)
        self.token = ""
        # where `note` takes its time (wall time live; a lab in one process gives its loop's)
        self.clock: Callable[[], float] = time.time
        self.on_note: Callable[[Device, Event], None] | None = None  # the lab's log

    # -- clock and timers ----------------------------------------------------------------------
    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        return asyncio.get_running_loop()

    def now(self) -> float:
        return asyncio.get_running_loop().time()

    def drive(self, core: Timed[Out], sink: Sink[Out], origin: float = 0.0) -> None:
        """Put the device's sans-I/O core on the one wall-clock driver (`timed.LoopTimer`): its
        timer outputs go to `sink`; `poke()` after every input moves the timer to its deadline.
        `origin`: the core's zero on the loop's clock (a train counts from its start)."""
        self.timer = LoopTimer(core, sink, origin=origin)

    def poke(self) -> None:
        if self.timer is not None:
            self.timer.poke()

    def note(self, kind: str, text: str) -> None:
        event = Event(time=self.clock(), kind=kind, text=text)
        self.events.append(event)
        if self.on_note is not None:
            self.on_note(self, event)
        log.info("%s %s: %s", self.name, kind, text)

    # -- control port ----------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind}

    async def command(self, obj: Message | Mapping[str, object]) -> dict[str, Any]:
        """One command: a message, or a JSON object decoded here, once, into one of the messages
        this kind takes (`messages`); one that is none of them gets the one error answer."""
        try:
            message = obj if isinstance(obj, Message) else decode(obj, self.messages)
        except BadMessage as exc:
            return answer(Refused(error=str(exc)))
        return answer(await self.handle(message))

    async def handle(self, message: Message) -> Answer:
        """Override to add commands (and name them in `messages`); the base knows status, events
        and stop."""
        match message:
            case Status():
                return StatusAnswer(status=self.status())
            case Events(last=n):
                return EventsAnswer(events=list(self.events)[-n:])
            case Stop():
                self.stop()
                return Answer()
        return Refused(error=f"unknown command {message.cmd()!r}")

    async def _handle(
        self, obj: Message | Mapping[str, object], peer: jsonlines.Peer
    ) -> dict[str, Any]:
        try:
            return await self.command(obj)
        except Exception as exc:  # a bad command must never take the device down
            log.exception("%s: command %r failed", self.name, obj)
            return {"ok": False, "error": f"{type(exc).__name__}: {exc}"}

    # -- life cycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        """Override: open links and servers (call super().start() first)."""
        host, port = self.control_address
        self._server = await jsonlines.serve(host, port, self._handle, token=self.token)
        host, port = net.server_address(self._server)
        self.ready_info["control"] = f"{host}:{port}"

    async def tasks(self) -> list[asyncio.Task[None]]:
        """Override: long-running tasks (links)."""
        return []

    async def close(self) -> None:
        if self.timer is not None:
            self.timer.cancel()
        if self._server is not None:
            self._server.close()

    async def end(self, tasks: list[asyncio.Task[None]]) -> None:
        """What the end of its process does, where it runs beside other devices in one process
        (a station's group, the lab in one process): its `tasks` cancelled -- its links and rails
        dropped -- and its ports closed; a close that fails ends it all the same."""
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        with contextlib.suppress(Exception):
            await self.close()

    def stop(self) -> None:
        if self._stop is not None:
            self._stop.set()

    def _lifeline_readable(self) -> None:
        assert self.lifeline is not None
        try:
            data = os.read(self.lifeline, 64)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self.loop.remove_reader(self.lifeline)
            log.warning("%s: the process that started it is gone; stopping", self.name)
            self.stop()

    async def launch(self, token: str) -> list[asyncio.Task[None]]:
        """Start the device (its control port obeys `token`, and so do the rails) and its
        long-running tasks: what `run` does before its "ready" line, and what a lab run in one
        process does for each device. An OSError (a port taken) closes it again and is raised."""
        self.token = token
        rails = getattr(self, "rails", None)
        if isinstance(rails, RailsClient):  # the rails are the lab's too: same token
            rails.token = self.token
        try:
            await self.start()
        except OSError:
            await self.close()
            raise
        return await self.tasks()

    async def run(self) -> int:
        self._stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, self.stop)
        if self.lifeline is not None:
            os.set_blocking(self.lifeline, False)
            loop.add_reader(self.lifeline, self._lifeline_readable)
        try:
            running = await self.launch(server_token(self.token_file)[0])
        except OSError as exc:  # a port taken, an address not ours: say so, no traceback
            log.error("%s cannot start: %s", self.name, exc)
            sys.stdout.write(json.dumps({"error": str(exc)}) + "\n")
            sys.stdout.flush()
            return 3
        ready: ReadyLine = {"ready": self.name, "kind": self.kind, **self.ready_info}
        sys.stdout.write(json.dumps(ready) + "\n")
        sys.stdout.flush()
        waiter = asyncio.ensure_future(self._stop.wait())
        try:
            done, _ = await asyncio.wait([waiter, *running], return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                if task is not waiter and task.exception() is not None:
                    log.error("%s: %s", self.name, task.exception())
                    return 3
            return 0
        finally:
            waiter.cancel()
            for task in running:
                task.cancel()
            await asyncio.gather(*running, return_exceptions=True)
            await self.close()

    def bind_code_link(
        self,
        peer: str,
        endpoint: Endpoint,
        charts: tuple[str, str],
        view: StationView,
        state: Callable[[], Mapping[str, int]],
        on_codes: Callable[[dict[str, int]], None],
        on_link: Callable[[bool], None],
        type1_profile: str,
        type1: LinkConfig | None,
        faults: frozenset[str],
    ) -> CodePort:
        """The one way a device binds a Type I link of code changes: to `peer` (its role, as
        `--link PEER=...` names it) at `endpoint`, sending chart `charts[0]` (the state `state`
        gives) and reading `charts[1]`, codes in to `on_codes`, the link's state to `on_link`; a
        pty it makes is in its ready line (`ptys`, by peer)."""
        binding = LinkBinding(*link_charts(view, charts[0]), state)
        port = CodePort(f"{self.name}-{peer}", endpoint, binding, on_codes, on_link,
                        type1_profile, type1, faults=faults)  # fmt: skip
        if port.path:
            self.ready_info.setdefault("ptys", {})[peer] = port.path
        return port


class IxlPeerDevice(Device):
    """A station device on a Type I link to its IXL (`--link ixl=...`) and on the rails
    (`--link rails=...`): the wayside ATC and the trackside. It sends its kind's chart to the IXL
    (`kinds`: "atc_to_ixl", "io_to_ixl") and reads the other way; subclasses give their core's
    state of it, and react to codes from the IXL, the link state and the rails."""

    def __init__(
        self,
        name: str,
        line: Line,
        station: int,
        links: dict[str, Endpoint],
        state: Callable[[], Mapping[str, int]],
        *,
        type1: LinkConfig | None = None,
        type1_profile: str = "ktcs-type1",
        control: tuple[str, int] = ("127.0.0.1", 0),
        faults: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(name, control)
        self.station = station
        self.port: CodePort | None = None
        if kinds.IXL in links:
            outward, inward = kinds.KINDS[self.kind].charts or ("", "")
            self.port = self.bind_code_link(
                kinds.IXL, links[kinds.IXL], (inward, outward), line.view(station), state,
                self.from_ixl, self.link_changed, type1_profile, type1, faults,
            )  # fmt: skip
        self.rails: RailsClient | None = None
        if kinds.RAILS in links:
            hello: Hello = {"role": self.kind, "name": name}
            lost = partial(self.rails_changed, False)
            self.rails = RailsClient(links[kinds.RAILS], hello, self.from_rails, lost)

    def from_ixl(self, codes: dict[str, int]) -> None:
        raise NotImplementedError

    def link_changed(self, up: bool) -> None:
        raise NotImplementedError

    def from_rails(self, obj: JsonObject) -> None:
        raise NotImplementedError

    def rails_changed(self, up: bool) -> None:
        """The rails (the source of occupancy) lost or back: the device goes fail-safe."""
        raise NotImplementedError

    async def start(self) -> None:
        await super().start()
        if self.rails is not None:
            self.rails_changed(False)  # nothing is known of occupancy until the rails report it

    async def tasks(self) -> list[asyncio.Task[None]]:
        out = [asyncio.ensure_future(self.port.run())] if self.port else []
        if self.rails is not None:
            out.append(asyncio.ensure_future(self.rails.run()))
        return out

    async def close(self) -> None:
        if self.port is not None:
            self.port.stop()
        await super().close()

    def status(self) -> dict[str, Any]:
        return {
            **super().status(),
            "station": self.station,
            "link": bool(self.port and self.port.up),
            "rails": bool(self.rails and self.rails.connected),
        }
