"""The IXL process: one station's `Interlocking` bound to its Type I links (ATC, trackside I/O,
and the neighbouring IXLs east and west: SPEC §6.6) and its Type II link to the CTC (as a client
that reconnects with back-off). Each link's codes go through its binding (`binding.LinkBinding`;
`ControlLink` for the CTC's controls): the interlocking takes and gives code names only. Each link
going up or down is one event in the device's log: the interlocking's own for the Type I links,
the device's for the CTC link."""

from __future__ import annotations

import asyncio
from functools import partial
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.binding import ControlLink
from ktcs_bench.emulator import variants
from ktcs_bench.emulator.code_link import CodePort
from ktcs_bench.emulator.device import Device
from ktcs_bench.errors import UsageError
from ktcs_bench.ixl.interlocking import LINKS, Interlocking, IxlOutput
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.messages import (
    IXL,
    Answer,
    Local,
    LocalControl,
    Message,
    ModeAnswer,
    ReasonAnswer,
    Refused,
)
from ktcs_bench.station.model import Line, StationView
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.transport.endpoints import Endpoint
from ktcs_bench.transport.ixl_client import IxlClient
from ktcs_bench.type1 import LinkConfig
from ktcs_bench.type2 import events as ev


def neighbour_roles(view: StationView) -> tuple[str, ...]:
    """The roles of the station's neighbouring IXLs: one per interval it shares with another
    station (not a lab edge), `east` where it is the interval's west end."""
    return tuple(
        kinds.neighbour_role(iv.west == view.number) for iv in view.intervals if not iv.boundary
    )


class IxlDevice(Device):
    kind = kinds.IXL
    messages = IXL

    def __init__(
        self,
        name: str,
        line: Line,
        station: int,
        links: dict[str, Endpoint],
        *,
        mode: Mode = Mode.CENTER,
        type1: LinkConfig | None = None,
        type1_profile: str = "ktcs-type1",
        control: tuple[str, int] = ("127.0.0.1", 0),
        faults: frozenset[str] = frozenset(),
        ssl: Any = None,
        server_hostname: str | None = None,
        restarted: bool = False,
    ) -> None:
        super().__init__(name, control)
        self.station = station
        view = line.view(station)
        neighbours = neighbour_roles(view)
        for role in kinds.NEIGHBOUR_ROLES:
            if role in links and role not in neighbours:
                raise UsageError(f"--link {role}=...: station {station} has no {role} "
                                 "neighbour (no interval on that side shared with a station)")  # fmt: skip
        # restarted in a running lab (a crash recovery): start-up locking (ixl.interlocking);
        # the neighbours it is linked with work its intervals' permission (SPEC §6.6)
        self.ixl = Interlocking(
            view, mode=mode, tc_sources=(kinds.ATC,), startup_locking=restarted,
            neighbour_links=tuple(r for r in neighbours if r in links),
        )  # fmt: skip
        self.drive(self.ixl, lambda now, out: self.apply(out))
        self.ports: dict[str, CodePort] = {}
        # the Type I peers and the neighbouring IXLs (SPEC §6.6): each link bound the one way,
        # the IXL sending ixl_to_ROLE and reading ROLE_to_ixl
        for role in (*LINKS, *self.ixl.neighbours):
            if role not in links:
                continue
            charts = (kinds.chart_name(role, True), kinds.chart_name(role, False))
            self.ports[role] = self.bind_code_link(
                role, links[role], charts, view, partial(self.ixl.full_state, role),
                partial(self._codes_from, role), partial(self._link_of, role),
                type1_profile, type1, faults,
            )  # fmt: skip
        # the application the Type II client serves: full states, controls by number
        self.ctc_link = ControlLink(
            *link_charts(view, kinds.chart_name(kinds.CTC, True)),
            partial(self.ixl.full_state, kinds.CTC),
            self._control, int(Reason.UNKNOWN_CODE), self._unknown_control,
        )  # fmt: skip
        self.ctc_endpoint = links.get(kinds.CTC)
        self.client: IxlClient | None = None
        self.ctc_up = False  # the Type II link as this device last logged it
        self.faults, self.ssl, self.server_hostname = faults, ssl, server_hostname

    # -- the CTC's controls, by name -------------------------------------------------------------
    def _control(self, name: str, value: int) -> tuple[bool, int] | None:
        """The interlocking's answer now; None when a departure waits for its interval's
        permission: `apply` sends the answer when the interlocking gives it."""
        out = self.ixl.control(name, value, self.now())
        result = next((r for r in out.results if not r.late), None)
        if result is not None:
            out.results.remove(result)
        self.apply(out)
        return None if result is None else (result.accepted, int(result.reason))

    def _unknown_control(self, code: int, value: int) -> None:
        self.note("control", f"ctc: unknown control code {code} rejected")

    # -- plumbing --------------------------------------------------------------------------------
    def _codes_from(self, role: str, codes: dict[str, int]) -> None:
        self.apply(self.ixl.receive(role, codes, self.now()))

    def _link_of(self, role: str, up: bool) -> None:
        self.apply(self.ixl.link_state(role, up, self.now()))

    def apply(self, out: IxlOutput) -> None:
        for role, changes in out.changes.items():
            if role in self.ports:
                self.ports[role].update(changes)
        if ctc := out.of(kinds.CTC):
            items = self.ctc_link.send(ctc)
            if items and self.client is not None:
                self.client.indicate(items)
        for late in out.results:  # answers to controls that waited (`_control`)
            if late.late and late.name is not None and self.client is not None:
                number = self.ctc_link.control_number(late.name)
                self.client.control_result(number, late.accepted, int(late.reason))
        for e in out.events:
            self.note(e.kind, e.text)
        self.poke()

    # -- life cycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        await super().start()
        ep = self.ctc_endpoint
        if ep is not None:
            self.client = variants.ixl_client(
                self.faults, self.station, ep.host, ep.port, self.ctc_link, ssl=self.ssl,
                server_hostname=self.server_hostname,
            )  # fmt: skip
            self.client.on_event = self._ctc_event
            self.client.start()

    def _ctc_event(self, station: int | None, event: ev.SessionEvent) -> None:
        """The CTC link's transitions in the device's log, one event each, in the words the
        interlocking logs its Type I links' ("atc link up"): up when the CTC accepts the
        station's IDENT, down when that session closes."""
        if isinstance(event, ev.IdentAccepted):
            self.ctc_up = True
            self.note("link", "ctc link up")
        elif isinstance(event, ev.Closed) and self.ctc_up:
            self.ctc_up = False
            self.note("link", f"ctc link down ({event.reason})")

    async def tasks(self) -> list[asyncio.Task[None]]:
        return [asyncio.ensure_future(p.run()) for p in self.ports.values()]

    async def close(self) -> None:
        for p in self.ports.values():
            p.stop()
        if self.client is not None:
            await self.client.close()
        await super().close()

    def status(self) -> dict[str, Any]:
        ixl = self.ixl
        return {
            **super().status(),
            "station": self.station,
            "mode": ixl.modes.mode.value,
            "links": {r: p.up for r, p in self.ports.items()}
            | {kinds.CTC: bool(self.client and self.client.identified)},
            "routes": {n: ixl.route_status(n).value for n in ixl.routes},
            "held": {
                n: sorted(rs.held_tcs | rs.held_points)
                for n, rs in ixl.routes.items()
                if rs.holds_anything
            },  # fmt: skip
            "startup_held": sorted(ixl.startup_held),  # start-up locking (ixl.interlocking)
            "points": {n: ixl.detection(n) for n in ixl.points},
            "signals": {n: ixl.aspect(n) for n in ixl.signals},
            "occupied": [t for t in ixl.tc_names if ixl.occupied(t)],
            "ctc_state": dict(self.ctc_link.full_state()),
        }

    async def handle(self, message: Message) -> Answer:
        match message:
            case LocalControl(code=code, value=value):  # the local panel: a code by name or number
                name = self.ctc_link.control_name(code) if isinstance(code, int) else code
                if name is None:
                    return ReasonAnswer(ok=False, reason=int(Reason.UNKNOWN_CODE))
                out = self.ixl.local_control(name, value, self.now())
                self.apply(out)
                r = out.results[0]
                return ReasonAnswer(ok=r.accepted, reason=int(r.reason))
            case Local(action=action):  # the local operator: grant | refuse | take (CMR handshake)
                try:
                    self.apply(self.ixl.local(action, self.now()))
                except ValueError as exc:
                    return Refused(error=str(exc))
                return ModeAnswer(mode=self.ixl.modes.mode.value)
        return await super().handle(message)
