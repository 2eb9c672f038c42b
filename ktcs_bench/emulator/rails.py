"""The field bus: what the rails carry between the track-circuit emulator and its clients.

The track-circuit emulator serves it (JSON lines over TCP, admitting only who presents the lab's
token, as every control port does). Clients say who they are first:
  {"hello": {"role": "atc"|"trackside"|"train"|"observer", "name": ..., "train": id}, "token": T}
then the server sends {"occupancy": {TC: 0|1}} (all on hello, changes after). An ATC sends
{"codes": {TC: [code, speed_kmh, gradient_permille, target_distance_m]}}; a train sends
{"position": {"head": m, "tail": m, "track": "1"}} and receives {"code": [...] | null} for the
track circuit under its antenna. Faults: {"fault": {"tc": NAME, "kind": KIND}}, {"clear": NAME|null}.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from ktcs_bench.transport import jsonlines
from ktcs_bench.transport.endpoints import Endpoint

log = logging.getLogger("ktcs_bench.emulator")
RETRY = 0.5  # s between connection attempts to the rails


class RailsClient:
    """A client of the field bus that reconnects; `on_message` gets every object from the server,
    `on_lost()` (if given) is called when a connection that was up is lost."""

    token: str | None = None  # presented with the hello (the rails are a lab's, like its ports)

    def __init__(
        self,
        endpoint: Endpoint,
        hello: dict[str, Any],
        on_message: Callable[[dict[str, Any]], None],
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        self.endpoint, self.hello, self.on_message = endpoint, hello, on_message
        self.on_lost = on_lost
        self.peer: jsonlines.Peer | None = None
        self._last: dict[
            str, dict[str, Any]
        ] = {}  # last object sent per key, replayed on reconnect

    @property
    def connected(self) -> bool:
        return self.peer is not None

    def send(self, obj: dict[str, Any]) -> None:
        for key, value in obj.items():
            if key in ("codes", "position"):
                self._last.setdefault(key, {})
                if key == "codes":
                    self._last[key].update(value)
                else:
                    self._last[key] = value
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
