"""The track-circuit emulator process: owns the line (`atc.TrackCircuitModel`) and serves the
rails -- positions in from trains, occupancy out to ATCs and trackside relays, each train the code
under its antenna -- with injectable track-circuit failures. It moves the trains by the blades
each trackside publishes; what the rails do to a train (a trailed point, a derailment, a misrouted
train) is an event of its log (`rails: trailed point 18 31 ...`), told to the train (it stops)
and, for a trailed point, to the trackside of its station (its detection is lost)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.atc.track_circuits import RailEvent, TrackCircuitModel, TrainPosition
from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.rails import code_from_wire
from ktcs_bench.messages import (
    TRACK_CIRCUITS,
    Answer,
    Clear,
    Fail,
    JsonObject,
    Message,
    Place,
    Refused,
    Remove,
)
from ktcs_bench.station.model import Line
from ktcs_bench.transport import jsonlines, net

OCCUPANCY_ROLES = (*(k.name for k in kinds.KINDS.values() if k.rails and k.station), "observer",
                   kinds.TRAIN)  # fmt: skip
"""Who on the rails is told the occupancy: the station devices on them (the ATC, the trackside),
observers, and trains (a timetable train comes onto the line only once its entry is clear)."""


class TrackCircuitDevice(Device):
    kind = kinds.TRACKCIRCUIT
    messages = TRACK_CIRCUITS

    def __init__(
        self,
        name: str,
        line: Line,
        listen: tuple[str, int],
        control: tuple[str, int] = ("127.0.0.1", 0),
    ) -> None:
        super().__init__(name, control)
        self.model = TrackCircuitModel(line)
        self.listen = listen
        # in the order they said hello: a broadcast goes out in the same order every run
        self.peers: dict[jsonlines.Peer, None] = {}
        self.trains: dict[str, jsonlines.Peer] = {}
        self._server2: Any = None

    def _occ(self, changes: dict[str, bool] | None = None) -> dict[str, int]:
        src = self.model.occupancy() if changes is None else changes
        return {k: int(v) for k, v in src.items()}

    def _broadcast(self, changes: dict[str, bool]) -> None:
        if changes:
            msg = {"occupancy": self._occ(changes)}
            for p in self.peers:
                if p.info.get("role") in OCCUPANCY_ROLES:
                    p.send(msg)
            self.note("occupancy", ", ".join(f"{k}={int(v)}" for k, v in sorted(changes.items())))
        self._rail_events()
        self._codes_to_trains()

    def _codes_to_trains(self) -> None:
        for train, peer in self.trains.items():
            if train not in self.model.trains:
                continue
            code = self.model.code_for(train)
            wire = None if code is None else [code.code, code.target_speed_kmh,
                                              code.gradient_permille, code.target_distance_m]  # fmt: skip
            if peer.info.get("last_code", "none") != wire:
                peer.info["last_code"] = wire
                peer.send({"code": wire, "tc": self.model.under_antenna(train)})

    async def _rails(self, obj: JsonObject, peer: jsonlines.Peer) -> Mapping[str, object] | None:
        if "hello" in obj and isinstance(obj["hello"], dict):
            peer.info.update(obj["hello"])
            self.peers[peer] = None
            if peer.info.get("role") == kinds.TRAIN and peer.info.get(kinds.TRAIN):
                self.trains[str(peer.info[kinds.TRAIN])] = peer
            return {"occupancy": self._occ(), "full": True}
        if "codes" in obj and isinstance(obj["codes"], dict):
            codes = {}
            for tc, v in obj["codes"].items():
                try:
                    codes[tc] = code_from_wire(v)
                except (TypeError, ValueError, IndexError):
                    return {"error": f"bad code for {tc}"}
            self.model.set_codes(codes)
            self._codes_to_trains()
            return None
        if "position" in obj and isinstance(obj["position"], dict):
            train = str(peer.info.get(kinds.TRAIN, peer.address))
            pos = obj["position"]
            try:
                track = pos.get("track")
                position = TrainPosition(
                    train, float(pos["head"]), float(pos["tail"]),
                    None if track is None else str(track), booked=track is not None,
                )  # fmt: skip
            except (KeyError, TypeError, ValueError):
                return {"error": "position needs head and tail in metres"}
            try:
                changes = self.model.move(position)
            except ValueError as exc:
                return {"error": str(exc)}
            self._broadcast(changes)
            return None
        if "blades" in obj and isinstance(obj["blades"], dict):
            blades = obj["blades"]
            points = blades.get("points")
            if not isinstance(points, dict):
                return {"error": "blades need station and points {POINT: position}"}
            try:
                station = int(blades["station"])
                changes = self.model.set_blades(
                    station, {str(k): str(v) for k, v in points.items()}
                )
            except (KeyError, TypeError, ValueError) as exc:
                return {"error": f"blades: {exc}"}
            self._broadcast(changes)
            return None
        return await self._handle(obj, peer)

    def _rail_events(self) -> None:
        """Log what the rails did to trains, and tell the train and (a trailed point) the
        trackside of the point's station."""
        for e in self.model.take_events():
            self.note("rails", e.text)
            train = self.trains.get(e.train)
            if e.kind == "trailed":
                for p in self.peers:
                    if p.info.get("role") == kinds.TRACKSIDE:
                        p.send({"trailed": {"station": e.station, "point": e.point, "leg": e.leg}})
            elif train is not None:
                train.send(self._to_train(e))

    @staticmethod
    def _to_train(e: RailEvent) -> JsonObject:
        if e.kind == "derailed":
            return {"derailed": f"{e.station} {e.point}"}
        return {"misrouted": {"track": e.track}}

    def _closed(self, peer: jsonlines.Peer) -> None:
        self.peers.pop(peer, None)
        train = peer.info.get(kinds.TRAIN)
        if train is not None and self.trains.get(str(train)) is peer:
            del self.trains[str(train)]
            self._broadcast(self.model.remove(str(train)))

    async def handle(self, message: Message) -> Answer:
        """fail (tc, kind), clear (tc, else every one), place (train, head, tail, track,
        direction: a train with no process of its own; placed again, it moves), remove (train)."""
        try:
            match message:
                case Fail(tc=tc, kind=kind):
                    self._broadcast(self.model.fail(tc, kind))
                case Clear(tc=tc):
                    self._broadcast(self.model.clear_fault(tc))
                case Place(train=train, head=head, tail=tail, track=track, direction=way):
                    if (head >= tail) != (way == "up"):
                        raise ValueError(f"train {train} faces {way}: its head must be "
                                         f"{'above' if way == 'up' else 'below'} its tail")  # fmt: skip
                    self._broadcast(self.model.move(TrainPosition(train, head, tail, track)))
                case Remove(train=train):
                    self._broadcast(self.model.remove(train))
                case _:
                    return await super().handle(message)
        except (KeyError, ValueError) as exc:
            return Refused(error=f"{type(exc).__name__}: {exc}")
        return Answer()

    async def start(self) -> None:
        await super().start()
        host, port = self.listen
        self._server2 = await jsonlines.serve(
            host, port, self._rails, self._closed, token=self.token
        )
        host, port = net.server_address(self._server2)
        self.ready_info["listen"] = f"{host}:{port}"

    async def close(self) -> None:
        if self._server2 is not None:
            self._server2.close()
        await super().close()

    def status(self) -> dict[str, Any]:
        return {
            **super().status(),
            "occupied": sorted(k for k, v in self.model.occupancy().items() if v),
            "faults": dict(self.model.faults),
            # head, tail and the station track the head is actually on (on the plain line, whose
            # track circuits carry every track: the track it was put on or booked, else "1")
            "trains": {
                k: [t.head_m, t.tail_m, self.model.track_of(k) or t.track or "1"]
                for k, t in self.model.trains.items()
            },
            "blades": {f"{st} {p}": b for (st, p), b in sorted(self.model.blades.items())},
            # the points each derailed train came off at ("18 31")
            "derailed": {
                k: sorted(f"{st} {p}" for st, p in path.derailed)
                for k, path in self.model.paths.items()
                if path.derailed
            },
        }
