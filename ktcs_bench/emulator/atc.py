"""The wayside ATC process: `atc.WaysideAtc` on a Type I link to its IXL, occupancy in from the
rails, a code per track circuit out to the rails (the most restrictive on communication error)."""

from __future__ import annotations

import asyncio
from dataclasses import astuple
from typing import Any

from ktcs_bench.atc.wayside import AtcOutput, WaysideAtc
from ktcs_bench.charts.generate import station_chart
from ktcs_bench.emulator.codeport import CodePort
from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.endpoints import Endpoint
from ktcs_bench.emulator.rails import RailsClient
from ktcs_bench.station.model import Line
from ktcs_bench.type1 import LinkConfig


class AtcDevice(Device):
    kind = "atc"

    def __init__(
        self,
        name: str,
        line: Line,
        station: int,
        links: dict[str, Endpoint],
        *,
        type1: LinkConfig | None = None,
        type1_profile: str = "ktcs-type1",
        control: tuple[str, int] = ("127.0.0.1", 0),
        faults: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(name, control)
        view = line.view(station)
        self.station = station
        self.atc = WaysideAtc(line, station)
        self.port: CodePort | None = None
        if "ixl" in links:
            self.port = CodePort(
                f"{name}-ixl", links["ixl"], station_chart(view, "atc_to_ixl"),
                station_chart(view, "ixl_to_atc"), self.atc.full_state(), self._from_ixl,
                self._link, type1_profile, type1, faults=faults,
            )  # fmt: skip
            if self.port.path:
                self.ready_info["ptys"] = {"ixl": self.port.path}
        self.rails = (
            RailsClient(links["rails"], {"role": "atc", "name": name}, self._from_rails)
            if "rails" in links
            else None
        )

    def _from_ixl(self, codes: dict[str, int]) -> None:
        self.apply(self.atc.receive(codes, self.now()))

    def _link(self, up: bool) -> None:
        self.apply(self.atc.link_state(up, self.now()))

    def _from_rails(self, obj: dict[str, Any]) -> None:
        occ = obj.get("occupancy")
        if isinstance(occ, dict):
            self.apply(self.atc.set_occupancy({k: bool(v) for k, v in occ.items()}, self.now()))
            if self.rails is not None and "full" in obj:  # a (re)connection: send every code
                self.rails.send({"codes": self._wire(self.atc.track_codes())})

    @staticmethod
    def _wire(codes: dict[str, Any]) -> dict[str, list[float]]:
        return {tc: list(astuple(code)) for tc, code in codes.items()}

    def apply(self, out: AtcOutput) -> None:
        if out.ixl and self.port is not None:
            self.port.update(out.ixl)
        if out.codes and self.rails is not None:
            self.rails.send({"codes": self._wire(out.codes)})
        for e in out.events:
            self.note(e.kind, e.text)

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
            "state": self.atc.full_state(),
            "sent": dict(self.port.state) if self.port else {},
            "rails": bool(self.rails and self.rails.connected),
            "codes": self._wire(self.atc.track_codes()),
        }
