"""`LiveLabAccess`: a running `lab up` as a `LabAccess` -- found by its state file (`state.attach`),
driven through its devices' and taps' control ports and its own, with the lab's token, in real
time over the real wires.

One connection per port is kept open and reused (a control port serves many commands on one
connection); a device that was restarted is reached again at the address the state file gives.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.lab.access import LabGone
from ktcs_bench.lab.state import attach
from ktcs_bench.messages import Message, encode
from ktcs_bench.runtime import read_token
from ktcs_bench.transport import jsonlines

REQUEST_TIMEOUT_S = 30.0  # a CTC command waits up to 10 s for its CONTROL_RESULT; a restart longer
RESTART_TIMEOUT_S = 120.0


class LiveLabAccess:
    """`LiveLabAccess.attach("reference")`; a PeerError (exit 3) when the lab is not up."""

    def __init__(self, name: str, state: dict[str, Any], token: str) -> None:
        self.name = name
        self._state = state
        self._token = token
        self._peers: dict[str, jsonlines.Peer] = {}
        self._locks: dict[str, asyncio.Lock] = {}

    @classmethod
    def attach(cls, name: str) -> LiveLabAccess:
        try:
            state = attach(name)
        except UsageError as exc:  # not running: for a test run, the lab is unreachable
            raise PeerError(str(exc)) from None
        try:
            token = read_token(Path(str(state.get("token_file"))))
        except (OSError, UsageError) as exc:
            raise PeerError(f"lab {name}: cannot read its token: {exc}") from None
        return cls(name, state, token)

    def _refresh(self) -> None:
        try:
            self._state = attach(self.name)
        except (UsageError, PeerError):
            pass

    # -- LabAccess ---------------------------------------------------------------------------------
    @property
    def devices(self) -> dict[str, str]:
        return {n: str(d.get("kind")) for n, d in self._state.get("devices", {}).items()}

    @property
    def links(self) -> list[str]:
        return [e["link"] for e in self._state.get("links", []) if e.get("a") and e.get("b")]

    def now(self) -> float:
        return asyncio.get_running_loop().time()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(seconds)

    def _device_address(self, name: str) -> str:
        d = self._state.get("devices", {}).get(name)
        if d is None:
            raise UsageError(f"lab {self.name} has no device {name!r}")
        return str(d.get("control", ""))

    def _link_address(self, name: str) -> str:
        for e in self._state.get("links", []):
            if e.get("link") == name and e.get("tap"):
                return str(e["tap"])
        raise UsageError(f"lab {self.name} has no tapped link {name!r}")

    async def device(self, name: str, obj: Message | Mapping[str, object]) -> dict[str, Any]:
        sent = encode(obj) if isinstance(obj, Message) else dict(obj)
        try:
            return await self._request(self._device_address(name), sent)
        except LabGone:
            raise
        except (OSError, TimeoutError, PeerError):
            self._refresh()  # restarted elsewhere? try once more where the state says it is
            return await self._request(self._device_address(name), sent)

    async def link(self, name: str, obj: Mapping[str, object]) -> dict[str, Any]:
        return await self._request(self._link_address(name), obj)

    async def lab(self, obj: Mapping[str, object]) -> dict[str, Any]:
        timeout = RESTART_TIMEOUT_S if obj.get("cmd") == "restart" else REQUEST_TIMEOUT_S
        answer = await self._request(str(self._state.get("control")), obj, timeout)
        if obj.get("cmd") in ("restart", "kill"):
            self._refresh()
            self._drop(self._device_address(str(obj.get("device"))))
        return answer

    def captures(self) -> dict[str, Path]:
        return {e["link"]: Path(e["capture"]) for e in self._state.get("links", [])
                if e.get("capture")}  # fmt: skip

    # -- the connections -------------------------------------------------------------------------
    async def _request(
        self, address: str, obj: Mapping[str, object], timeout: float = REQUEST_TIMEOUT_S
    ) -> dict[str, Any]:
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise PeerError(f"lab {self.name}: no address for that port ({address!r})")
        lock = self._locks.setdefault(address, asyncio.Lock())
        async with lock:
            peer = self._peers.get(address)
            try:
                async with asyncio.timeout(timeout):
                    if peer is None:
                        peer = await jsonlines.connect(host, int(port))
                        self._peers[address] = peer
                        peer.send({**obj, "token": self._token})
                    else:
                        peer.send(obj)
                    answer = await peer.read()
            except (OSError, TimeoutError, ValueError) as exc:
                self._drop(address)
                self._still_up()
                raise PeerError(f"{address}: {exc or type(exc).__name__}") from None
            except asyncio.CancelledError:  # its answer would be read as the next one's
                self._drop(address)
                raise
            if answer is None:
                self._drop(address)
                raise PeerError(f"{address} closed without answering")
            if answer.get("refused"):
                self._drop(address)
                raise PeerError(f"{address} {answer.get('error')}")
            return answer

    def _still_up(self) -> None:
        """LabGone unless the lab's process still runs."""
        try:
            self._state = attach(self.name)
        except (UsageError, PeerError) as exc:
            raise LabGone(f"lab {self.name} stopped: {exc}") from None

    def _drop(self, address: str) -> None:
        peer = self._peers.pop(address, None)
        if peer is not None:
            peer.close()

    async def close(self) -> None:
        for address in list(self._peers):
            self._drop(address)
