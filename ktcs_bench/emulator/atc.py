"""The wayside ATC process: `atc.WaysideAtc` on a Type I link to its IXL, occupancy in from the
rails, a code per track circuit out to the rails (the most restrictive on communication error).
Until the rails connect, and whenever their connection is lost, every track circuit is occupied."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.atc.track_codes import AtcCode
from ktcs_bench.atc.wayside import AtcOutput, WaysideAtc
from ktcs_bench.emulator.device import IxlPeerDevice
from ktcs_bench.emulator.rails import WireCode, code_to_wire
from ktcs_bench.messages import JsonObject
from ktcs_bench.station.model import Line
from ktcs_bench.transport.endpoints import Endpoint


class AtcDevice(IxlPeerDevice):
    kind = kinds.ATC

    def __init__(
        self, name: str, line: Line, station: int, links: dict[str, Endpoint], **kwargs: Any
    ) -> None:
        self.atc = WaysideAtc(line, station)
        super().__init__(name, line, station, links, self.atc.full_state, **kwargs)

    def from_ixl(self, codes: dict[str, int]) -> None:
        self.apply(self.atc.receive(codes, self.now()))

    def link_changed(self, up: bool) -> None:
        self.apply(self.atc.link_state(up, self.now()))

    def rails_changed(self, up: bool) -> None:
        self.apply(self.atc.rails_state(up, self.now()))

    def from_rails(self, obj: JsonObject) -> None:
        occ = obj.get("occupancy")
        if isinstance(occ, dict):
            if "full" in obj:  # the rails (back): every track circuit reported
                self.rails_changed(True)
            self.apply(self.atc.set_occupancy({k: bool(v) for k, v in occ.items()}, self.now()))
            if self.rails is not None and "full" in obj:  # a (re)connection: send every code
                self.rails.send({"codes": self._wire(self.atc.track_codes())})

    @staticmethod
    def _wire(codes: Mapping[str, AtcCode]) -> dict[str, WireCode]:
        return {tc: code_to_wire(code) for tc, code in codes.items()}

    def apply(self, out: AtcOutput) -> None:
        if out.ixl and self.port is not None:
            self.port.update(out.ixl)
        if out.codes and self.rails is not None:
            self.rails.send({"codes": self._wire(out.codes)})
        for e in out.events:
            self.note(e.kind, e.text)

    def status(self) -> dict[str, Any]:
        return {
            **super().status(),
            "state": self.atc.full_state(),
            "sent": dict(self.port.state) if self.port else {},
            "rails": bool(self.rails and self.rails.connected),
            "codes": self._wire(self.atc.track_codes()),
        }
