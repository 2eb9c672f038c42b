"""The trackside I/O process: point machines, signal lamps and track relays (`field.Trackside`)
on a Type I link to their IXL, with track occupancy from the rails and a fault API."""

from __future__ import annotations

import asyncio
from typing import Any

from ktcs_bench.charts.generate import station_chart
from ktcs_bench.emulator.codeport import CodePort
from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.endpoints import Endpoint
from ktcs_bench.emulator.rails import RailsClient
from ktcs_bench.field.trackside import FieldOutput, Trackside
from ktcs_bench.station.model import Line
from ktcs_bench.type1 import LinkConfig


class TracksideDevice(Device):
    kind = "trackside"

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
        self.io = Trackside(view)
        self.port: CodePort | None = None
        if "ixl" in links:
            self.port = CodePort(
                f"{name}-ixl", links["ixl"], station_chart(view, "io_to_ixl"),
                station_chart(view, "ixl_to_io"), self.io.full_state(), self._from_ixl,
                self._link, type1_profile, type1, faults=faults,
            )  # fmt: skip
            if self.port.path:
                self.ready_info["ptys"] = {"ixl": self.port.path}
        self.rails = (
            RailsClient(links["rails"], {"role": "trackside", "name": name}, self._from_rails)
            if "rails" in links
            else None
        )

    def _from_ixl(self, codes: dict[str, int]) -> None:
        self.apply(self.io.receive(codes, self.now()))

    def _link(self, up: bool) -> None:
        self.apply(self.io.link_state(up, self.now()))

    def _from_rails(self, obj: dict[str, Any]) -> None:
        occ = obj.get("occupancy")
        if isinstance(occ, dict):
            mine = {k: bool(v) for k, v in occ.items() if k in self.io.relays}
            if mine:
                self.apply(self.io.set_occupancy(mine, self.now()))

    def apply(self, out: FieldOutput) -> None:
        if out.changes and self.port is not None:
            self.port.update(out.changes)
        for e in out.events:
            self.note(e.kind, e.text)
        self.arm(self.io.next_deadline())

    def tick(self) -> None:
        self.apply(self.io.tick(self.now()))

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
            "state": self.io.full_state(),
        }

    async def command(self, obj: dict[str, Any]) -> dict[str, Any]:
        """Faults: {"cmd": "fail_point", "point", "kind"}, fail_lamp (signal, aspect),
        fail_track_circuit (tc, kind), clear_faults."""
        cmd, now = obj.get("cmd"), self.now()
        try:
            if cmd == "fail_point":
                self.apply(self.io.fail_point(obj["point"], obj["kind"], now))
            elif cmd == "fail_lamp":
                self.apply(self.io.fail_lamp(obj["signal"], obj["aspect"], now))
            elif cmd == "fail_track_circuit":
                self.apply(self.io.fail_track_circuit(obj["tc"], obj["kind"], now))
            elif cmd == "clear_faults":
                self.apply(self.io.clear_faults(now))
            else:
                return await super().command(obj)
        except (KeyError, ValueError) as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": True}
