"""A Type I link that carries one code chart each way, as named states (SPEC §3.3–3.5).

Outgoing: `update(changes)` sends the core's code changes as CHANGE items (Sequence, status), and
REQUEST_ALL from the peer is answered with ALL_INFO from the binding's table (the link's state
provider). Incoming: CHANGE and ALL_INFO become {name: state}. Link up / communication error are
passed on so the application reacts fail-safe. Names, numbers, the table and what is owed after an
outage are the `binding.LinkBinding`'s; the link logic is `type1.Type1Link`; this runs them on a
serial endpoint or a pty.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping

from ktcs_bench.binding import LinkBinding
from ktcs_bench.emulator import variants
from ktcs_bench.errors import KtcsError
from ktcs_bench.transport.aio import LinkRunner
from ktcs_bench.transport.base import Transport
from ktcs_bench.transport.endpoints import Endpoint
from ktcs_bench.transport.serialport import open_transport
from ktcs_bench.type1 import (
    CommunicationError,
    LinkConfig,
    LinkDown,
    LinkEvent,
    LinkUp,
    MessageReceived,
    Type1Link,
)

log = logging.getLogger("ktcs_bench.emulator")
REOPEN = 1.0  # s between attempts to reopen a failed serial endpoint


class CodePort:
    def __init__(
        self,
        name: str,
        endpoint: Endpoint,
        binding: LinkBinding,
        on_codes: Callable[[dict[str, int]], None],
        on_link: Callable[[bool], None],
        profile: str = "ktcs-type1",
        config: LinkConfig | None = None,
        on_event: Callable[[str, LinkEvent], None] | None = None,
        faults: frozenset[str] = frozenset(),
    ) -> None:
        self.name = name
        self.binding = binding
        self.on_codes, self.on_link, self.on_event = on_codes, on_link, on_event
        self.profile, self.config, self.faults = profile, config, faults
        self.endpoint = endpoint
        if endpoint.kind not in ("pty", "serial"):
            raise ValueError(f"a Type I link needs a serial endpoint or pty, not {endpoint}")
        self.link = self._new_link()
        self.transport: Transport | None = None
        self.path: str | None = None
        if endpoint.kind == "pty":  # made now, so the path can be printed before the peer starts
            self.transport = open_transport("pty", name, self.link.config.line_rate)
            self.path = getattr(self.transport, "path", None)
        self.runner: LinkRunner | None = None
        self.frames_in = 0
        self._stopping = False

    @property
    def up(self) -> bool:
        return self.binding.up

    @property
    def state(self) -> dict[str, int]:
        """What the link carries: every transmit code's state."""
        return self.binding.sent()

    def _new_link(self) -> Type1Link:
        return variants.type1_link(
            self.faults, self.profile, self.config, self.name, self._statuses
        )

    async def run(self) -> None:
        """Run the link; a serial endpoint that fails (the peer's pty went away, a USB adapter
        was unplugged) is reported down and reopened every `REOPEN` seconds."""
        while not self._stopping:
            try:
                if self.transport is None:
                    self.transport = open_transport(
                        self.endpoint.address, self.name, self.link.config.line_rate,
                        profile=self.link.profile,
                    )  # fmt: skip
                self.runner = LinkRunner(self.link, self.transport, self._event)
                await self.runner.run()
                return
            except (KtcsError, OSError) as exc:
                if self.endpoint.kind == "pty":
                    raise
                log.warning("%s: %s; reopening in %.0f s", self.name, exc, REOPEN)
            finally:
                if self.endpoint.kind != "pty" and self.transport is not None:
                    self.transport.close()
                    self.transport = None
            if self.up:
                self.binding.link_down()
                self.on_link(False)
            self.link = self._new_link()
            await asyncio.sleep(REOPEN)

    def stop(self) -> None:
        self._stopping = True
        if self.runner is not None:
            self.runner.stop()

    def update(self, changes: Mapping[str, int] | list[tuple[str, int]]) -> None:
        """Send the core's code changes as CHANGE frames (while the link is down the binding owes
        them: the peer may already hold an ALL_INFO older than these)."""
        pairs = changes.items() if isinstance(changes, Mapping) else changes
        self._send_items(self.binding.send(pairs))

    def _send_items(self, items: list[tuple[int, int]]) -> None:
        if not items or self.runner is None:
            return
        per_frame = self.link.profile.items_per_frame("CHANGE")  # as wide as the profile's items
        for k in range(0, len(items), per_frame):
            chunk = [list(item) for item in items[k : k + per_frame]]
            self.runner.send(self.link.message("CHANGE", items=chunk))

    def _statuses(self, start: int, count: int) -> bytes:
        return bytes(self.binding.statuses()[start : start + count])

    def _event(self, now: float, event: LinkEvent) -> None:
        if self.on_event is not None:
            self.on_event(self.name, event)
        if isinstance(event, MessageReceived):
            self.frames_in += 1
            name = event.message.name
            if name == "CHANGE":
                out, unknown = self.binding.received(event.fields.get("items", []))
                for code in unknown:
                    log.warning("%s: CHANGE for code %d not in %s", self.name, code,
                                self.binding.rx.name)  # fmt: skip
                if out:
                    self.on_codes(out)
            elif name == "ALL_INFO":
                self.on_codes(self.binding.received_all(event.fields.get("statuses", [])))
        elif isinstance(event, LinkUp):
            log.info("%s: link up", self.name)
            self._send_items(self.binding.link_up())
            self.on_link(True)
        elif isinstance(event, LinkDown | CommunicationError):
            # what was queued (CHANGE, or the ALL_INFO answering the peer's REQUEST_ALL) was
            # discarded, and the peer may not have noticed the outage: push everything on recovery
            if self.up:
                log.warning("%s: link down (%s)", self.name, type(event).__name__)
            self.binding.link_down()
            self.on_link(False)


async def run_ports(ports: list[CodePort]) -> None:
    await asyncio.gather(*(p.run() for p in ports))
