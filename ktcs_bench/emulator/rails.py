"""The field bus: what the rails carry between the track-circuit emulator and its clients.

The track-circuit emulator serves it (JSON lines over TCP, admitting only who presents the lab's
token, as every control port does). Clients say who they are first:
  {"hello": {"role": "atc"|"trackside"|"train"|"observer", "name": ..., "train": id}, "token": T}
then the server sends {"occupancy": {TC: 0|1}} (all on hello, changes after). An ATC sends
{"codes": {TC: [code, speed_kmh, gradient_permille, target_distance_m, direction]}} -- direction
"up", "down" or null (any train: the most restrictive code); a code of 4 elements (an older
sender) has no direction (`code_from_wire`, `code_to_wire`); a train sends
{"position": {"head": m, "tail": m, "track": "1"}} and receives {"code": [...] | null} for the
track circuit under its antenna. Faults: {"fault": {"tc": NAME, "kind": KIND}}, {"clear": NAME|null}.

The blades (SPEC §6.7): a trackside sends where its points' blades are, every point of its
station each time one changes: {"blades": {"station": 18, "points": {"31": "normal"|"reverse"|
"moving"|"none"}}}, and the server moves trains by them. A train that trails a point makes the
server tell the tracksides {"trailed": {"station": 18, "point": "31", "leg": "reverse"}} (the
blades forced to that leg; the station's trackside loses the point's detection until a fault
clear). A train the rails derail is told {"derailed": "18 31"}, a timetable train off its booked
track {"misrouted": {"track": "2"}}; the "track" of a train's position is its booked track there.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Required, TypedDict

from ktcs_bench.atc.track_codes import AtcCode
from ktcs_bench.messages import JsonObject
from ktcs_bench.station.model import DIRECTIONS
from ktcs_bench.transport import jsonlines
from ktcs_bench.transport.endpoints import Endpoint

log = logging.getLogger("ktcs_bench.emulator")
RETRY = 0.5  # s between connection attempts to the rails


class Hello(TypedDict, total=False):
    """Who a client is: its role (its kind, or "observer"), its name, a train its id (under its
    kind's name: the track circuits read it as `kinds.TRAIN`)."""

    role: Required[str]
    name: Required[str]
    train: str


class Position(TypedDict, total=False):
    """Where a train is: its head and tail in metres, the track it is on if it is on one."""

    head: Required[float]
    tail: Required[float]
    track: str


class Blades(TypedDict):
    """Where the blades of a station's points are (see the module docstring)."""

    station: int
    points: dict[str, str]


WireCode = list[float | str | None]
"""A code on the rails: [code, speed_kmh, gradient_permille, target_distance_m, direction]."""


def code_to_wire(code: AtcCode) -> WireCode:
    return [code.code, code.target_speed_kmh, code.gradient_permille, code.target_distance_m,
            code.direction]  # fmt: skip


def code_from_wire(value: object) -> AtcCode:
    """A code from the rails; ValueError (or TypeError) when it is not one."""
    if not isinstance(value, list | tuple) or len(value) not in (4, 5):
        raise ValueError(f"a code is 4 or 5 elements, not {value!r}")
    direction = value[4] if len(value) == 5 else None
    if direction not in (None, *DIRECTIONS):
        raise ValueError(f"a code's direction is up, down or null, not {direction!r}")
    return AtcCode(int(value[0]), float(value[1]), float(value[2]), float(value[3]), direction)


class ToRails(TypedDict, total=False):
    """What a client sends once it has said hello: an ATC its codes, a train its position, a
    trackside its blades."""

    codes: dict[str, WireCode]
    position: Position
    blades: Blades


class RailsClient:
    """A client of the field bus that reconnects; `on_message` gets every object from the server,
    `on_lost()` (if given) is called when a connection that was up is lost."""

    token: str | None = None  # presented with the hello (the rails are a lab's, like its ports)

    def __init__(
        self,
        endpoint: Endpoint,
        hello: Hello,
        on_message: Callable[[JsonObject], None],
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        self.endpoint, self.hello, self.on_message = endpoint, hello, on_message
        self.on_lost = on_lost
        self.peer: jsonlines.Peer | None = None
        self._last: ToRails = {}  # the last of each key sent, replayed on reconnect

    @property
    def connected(self) -> bool:
        return self.peer is not None

    def send(self, obj: ToRails) -> None:
        if "codes" in obj:
            self._last.setdefault("codes", {}).update(obj["codes"])
        if "position" in obj:
            self._last["position"] = obj["position"]
        if "blades" in obj:
            self._last["blades"] = obj["blades"]
        if self.peer is not None:
            self.peer.send(obj)

    async def run(self) -> None:
        while True:
            try:
                self.peer = await jsonlines.connect(self.endpoint.host, self.endpoint.port)
            except OSError:
                await asyncio.sleep(RETRY)
                continue
            try:
                self.peer.send({"hello": self.hello, "token": self.token})
                for key, value in self._last.items():
                    self.peer.send({key: value})
                while True:
                    try:
                        obj = await self.peer.read()
                    except ValueError as exc:
                        log.warning("rails: %s", exc)
                        continue
                    if obj is None:
                        break
                    if obj.get("refused"):  # not our lab's rails, or not our token
                        log.error("rails at %s: %s", self.endpoint, obj.get("error"))
                        break
                    self.on_message(obj)
            except ConnectionError:
                pass
            finally:
                self.peer.close()
                self.peer = None
            log.warning("rails connection lost; reconnecting")
            if self.on_lost is not None:
                self.on_lost()
            await asyncio.sleep(RETRY)
