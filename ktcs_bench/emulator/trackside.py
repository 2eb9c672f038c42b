"""The trackside I/O process: point machines, signal lamps and track relays (`field.Trackside`)
on a Type I link to their IXL, with track occupancy from the rails and a fault API. Until the
rails connect, and whenever their connection is lost, every track relay reports occupied. It
publishes where its points' blades are on the rails (trains run by them), and a point the rails
say a train trailed loses its detection until `clear_faults`."""

from __future__ import annotations

from typing import Any

from ktcs_bench import kinds
from ktcs_bench.emulator.device import IxlPeerDevice
from ktcs_bench.field.trackside import FieldOutput, Trackside
from ktcs_bench.messages import (
    TRACKSIDE,
    Answer,
    ClearFaults,
    FailLamp,
    FailPoint,
    FailTrackCircuit,
    JsonObject,
    Message,
    Refused,
)
from ktcs_bench.station.model import Line
from ktcs_bench.transport.endpoints import Endpoint


class TracksideDevice(IxlPeerDevice):
    kind = kinds.TRACKSIDE
    messages = TRACKSIDE

    def __init__(
        self, name: str, line: Line, station: int, links: dict[str, Endpoint], **kwargs: Any
    ) -> None:
        self.io = Trackside(line.view(station))
        super().__init__(name, line, station, links, self.io.full_state, **kwargs)
        self.drive(self.io, lambda now, out: self.apply(out))
        self._blades: dict[str, str] = {}
        self._publish_blades()

    def from_ixl(self, codes: dict[str, int]) -> None:
        self.apply(self.io.receive(codes, self.now()))

    def link_changed(self, up: bool) -> None:
        self.apply(self.io.link_state(up, self.now()))

    def rails_changed(self, up: bool) -> None:
        self.apply(self.io.rails_state(up, self.now()))

    def from_rails(self, obj: JsonObject) -> None:
        occ = obj.get("occupancy")
        if isinstance(occ, dict):
            if "full" in obj:  # the rails (back): every track circuit reported
                self.rails_changed(True)
            mine = {k: bool(v) for k, v in occ.items() if k in self.io.relays}
            if mine:
                self.apply(self.io.set_occupancy(mine, self.now()))
        trailed = obj.get("trailed")
        if isinstance(trailed, dict) and trailed.get("station") == self.station:
            point, leg = str(trailed.get("point")), str(trailed.get("leg"))
            if point in self.io.points:
                try:
                    self.apply(self.io.trail(point, leg, self.now()))
                except ValueError as exc:
                    self.note("rails", f"trailed point not understood: {exc}")

    def _publish_blades(self) -> None:
        """Tell the rails where the blades are when that changed (the client replays the last
        on reconnect)."""
        blades = self.io.blades()
        if blades != self._blades and self.rails is not None:
            self._blades = blades
            self.rails.send({"blades": {"station": self.station, "points": blades}})

    def apply(self, out: FieldOutput) -> None:
        if out.changes and self.port is not None:
            self.port.update(out.changes)
        for e in out.events:
            self.note(e.kind, e.text)
        self._publish_blades()
        self.poke()

    def status(self) -> dict[str, Any]:
        return {
            **super().status(),
            "state": self.io.full_state(),
            # where the blades are (None between positions), whatever detection reports
            "machines": {
                p: {
                    "position": m.position,
                    "target": m.target,
                    "moving": m.moving,
                    "fault": m.fault,
                }
                for p, m in self.io.points.items()
            },  # fmt: skip
        }

    async def handle(self, message: Message) -> Answer:
        """Faults: fail_point (point, kind), fail_lamp (signal, aspect), fail_track_circuit (tc,
        kind), clear_faults."""
        now = self.now()
        try:
            match message:
                case FailPoint(point=point, kind=kind):
                    self.apply(self.io.fail_point(point, kind, now))
                case FailLamp(signal=signal, aspect=aspect):
                    self.apply(self.io.fail_lamp(signal, aspect, now))
                case FailTrackCircuit(tc=tc, kind=kind):
                    self.apply(self.io.fail_track_circuit(tc, kind, now))
                case ClearFaults():
                    self.apply(self.io.clear_faults(now))
                case _:
                    return await super().handle(message)
        except (KeyError, ValueError) as exc:
            return Refused(error=str(exc))
        return Answer()
