"""A Type I link that carries one code chart each way, as named states (SPEC §3.3–3.5).

Outgoing: the device's full state of its transmit chart; `update(changes)` sends CHANGE items
(Sequence, status) for what changed, and REQUEST_ALL from the peer is answered with ALL_INFO from
the same table (the link's state provider). Incoming: CHANGE and ALL_INFO become {name: state} for
the receive chart. Link up / communication error are passed on so the application reacts
fail-safe. The link logic itself is `type1.Type1Link`; this is only the chart <-> frame binding.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping

from ktcs_bench.charts.model import CodeChart
from ktcs_bench.emulator import variants
from ktcs_bench.errors import KtcsError
from ktcs_bench.transport.aio import LinkRunner
from ktcs_bench.transport.base import Transport
from ktcs_bench.transport.endpoints import Endpoint
from ktcs_bench.transport.serialport import open_transport
from ktcs_bench.type1 import (
    CommunicationError,
    Event,
    LinkConfig,
    LinkDown,
    LinkUp,
    MessageReceived,
    Type1Link,
)

log = logging.getLogger("ktcs_bench.emulator")
REOPEN = 1.0  # s between attempts to reopen a failed serial endpoint
MAX_ITEMS = 300  # CHANGE items a frame: 900 bytes, inside the default 1024-byte DATA limit


class CodePort:
    def __init__(
        self,
        name: str,
        endpoint: Endpoint,
        tx_chart: CodeChart,
        rx_chart: CodeChart,
        state: Mapping[str, int],
        on_codes: Callable[[dict[str, int]], None],
        on_link: Callable[[bool], None],
        profile: str = "ktcs-type1",
        config: LinkConfig | None = None,
        on_event: Callable[[str, Event], None] | None = None,
        faults: frozenset[str] = frozenset(),
    ) -> None:
        self.name = name
        self.tx_chart, self.rx_chart = tx_chart, rx_chart
        self.state = {c.name: int(state.get(c.name, 0)) for c in tx_chart.codes}
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
        self.up = False
        self.runner: LinkRunner | None = None
        self.frames_in = 0
        self._stopping = False
        self._unsent: set[str] = set()

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
                        self.endpoint.address, self.name, self.link.config.line_rate
                    )
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
                self.up = False
                self.on_link(False)
            self.link = self._new_link()
            await asyncio.sleep(REOPEN)

    def stop(self) -> None:
        self._stopping = True
        if self.runner is not None:
            self.runner.stop()

    def update(self, changes: Mapping[str, int] | list[tuple[str, int]]) -> None:
        """Record changes of the transmit chart and send them as CHANGE frames (if the link is up;
        otherwise the next REQUEST_ALL carries them)."""
        pairs = changes.items() if isinstance(changes, Mapping) else changes
        items = []
        for name, value in pairs:
            if name in self.state and self.state[name] != int(value):
                self.state[name] = int(value)
                items.append([self.tx_chart.number_of(name), int(value)])
        if not items:
            return
        if not self.up or self.runner is None:
            # the peer may already hold an ALL_INFO older than this: send these when the link is up
            self._unsent.update(self.tx_chart.name_of(code) or "" for code, _ in items)
            return
        self._send_items(items)

    def _send_items(self, items: list[list[int]]) -> None:
        assert self.runner is not None
        for k in range(0, len(items), MAX_ITEMS):
            self.runner.send(self.link.message("CHANGE", items=items[k : k + MAX_ITEMS]))

    def _statuses(self, start: int, count: int) -> bytes:
        values = [self.state[c.name] for c in self.tx_chart.codes]
        return bytes(values[start : start + count])

    def _event(self, now: float, event: Event) -> None:
        if self.on_event is not None:
            self.on_event(self.name, event)
        if isinstance(event, MessageReceived):
            self.frames_in += 1
            name = event.message.name
            if name == "CHANGE":
                out = {}
                for code, value in event.fields.get("items", []):
                    cname = self.rx_chart.name_of(code)
                    if cname is None:
                        log.warning(
                            "%s: CHANGE for code %d not in %s", self.name, code, self.rx_chart.name
                        )
                    else:
                        out[cname] = value
                if out:
                    self.on_codes(out)
            elif name == "ALL_INFO":
                statuses = event.fields.get("statuses", [])
                full = {
                    c.name: statuses[c.number - 1]
                    for c in self.rx_chart.codes
                    if c.number <= len(statuses)
                }
                self.on_codes(full)
        elif isinstance(event, LinkUp):
            self.up = True
            log.info("%s: link up", self.name)
            if self._unsent and self.runner is not None:
                names, self._unsent = self._unsent, set()
                self._send_items(
                    [[self.tx_chart.number_of(n), self.state[n]] for n in sorted(names) if n]
                )
            self.on_link(True)
        elif isinstance(event, LinkDown | CommunicationError):
            # what was queued (CHANGE, or the ALL_INFO answering the peer's REQUEST_ALL) was
            # discarded, and the peer may not have noticed the outage: push everything on recovery
            self._unsent.update(self.state)
            if self.up:
                log.warning("%s: link down (%s)", self.name, type(event).__name__)
            self.up = False
            self.on_link(False)


async def run_ports(ports: list[CodePort]) -> None:
    await asyncio.gather(*(p.run() for p in ports))
