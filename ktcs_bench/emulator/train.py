"""The train process: one `train.TrainEndpoint` (dynamics + onboard ATP + ATO) cycling every
100 ms of wall time on the loop's clock (`timed.aio.LoopTimer`: the cycle is the endpoint's
deadline), in kTCS mode -- its antenna reads the code of the track circuit under its head from
the rails, and its axles (head..tail) occupy track circuits there.

The process passes each code on as read -- located on the line: its track circuit's ends, its
speed, gradient and target distance (`TrackCode.read`) -- and the endpoint gives it its meaning
(the speed at the circuit's exit, the stop point, the ceiling inside the circuit). No code at the
antenna (none received yet, a dead track circuit, the rails lost) means stop here: a train never
runs on the absence of a code.

The train's line data (tags, gradients, speed limits) come from the lab's line file, so the ATP
and the wayside ATC see the same line. Runs in the up direction (rising chainage).
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.rails import RailsClient
from ktcs_bench.errors import UsageError
from ktcs_bench.station.model import Line
from ktcs_bench.train.deceleration import GradientProfile
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import (
    CYCLE,
    CycleInputs,
    CycleOutputs,
    LineData,
    TrackCode,
    TrainConfig,
    TrainEndpoint,
)
from ktcs_bench.train.mrsp import Restriction
from ktcs_bench.train.speed_distance import endpoint_speed_distance
from ktcs_bench.train.units import kmh
from ktcs_bench.transport.endpoints import Endpoint


def train_line(line: Line) -> LineData:
    """The onboard view of a reference line: tags every `tag_spacing_m`, gradients, speed limits."""
    tags = []
    x = line.start_m
    while x <= line.end_m:
        tags.append(x)
        x += line.tag_spacing_m
    grads = sorted(line.gradients, key=lambda g: g.from_m)
    gradient = GradientProfile(tuple(g.from_m for g in grads), tuple(g.permille for g in grads))
    restrictions = [Restriction(s.from_m, s.to_m, kmh(s.kmh)) for s in line.speed_limits]
    return LineData(line.end_m, tags, gradient, restrictions, [])


def _code_fields(wire: Any) -> tuple[float, float, float] | None:
    """(speed km/h, gradient ‰, target distance m) of a rails code [code, speed, gradient,
    distance], or None unless it is four finite numbers with speed and distance ≥ 0."""
    if not isinstance(wire, list) or len(wire) != 4:
        return None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in wire):
        return None
    speed, gradient, distance = (float(v) for v in wire[1:])
    if not all(math.isfinite(v) for v in (speed, gradient, distance)):
        return None
    return (speed, gradient, distance) if speed >= 0.0 and distance >= 0.0 else None


class TrainDevice(Device):
    kind = "train"

    def __init__(
        self,
        name: str,
        line: Line,
        config: TrainConfig,
        rails: Endpoint,
        control: tuple[str, int] = ("127.0.0.1", 0),
    ) -> None:
        super().__init__(name, control)
        self.line = line
        self.config = config
        # the first cycle one period after the start, on the train's own time (0 at the start)
        self.endpoint = TrainEndpoint(config, train_line(line), sense=self._sense, first=CYCLE)
        self.tcs = {t.name: t for t in line.all_track_circuits()}
        self.code: TrackCode | None = None
        self.code_tc: str | None = None
        self.rails = RailsClient(rails, {"role": "train", "name": name, "train": config.train_id},
                                 self._from_rails)  # fmt: skip
        self.last: Any = None
        self.release = False

    @classmethod
    def from_args(
        cls, name: str, lab: Any, line: Line, links: dict[str, Endpoint], train: str | None,
        control: tuple[str, int],
    ) -> TrainDevice:  # fmt: skip
        spec = lab.devices.get(name)
        opts = dict(spec.options) if spec is not None else {}
        if "rails" not in links:
            raise UsageError(
                "emulator train needs --link rails=tcp://HOST:PORT (the track circuits)"
            )
        params = TrainParams(
            length=float(opts.get("length_m", 100.0)),
            max_speed=kmh(float(opts.get("max_speed_kmh", 80.0))),
            brake_build_up=float(opts.get("brake_build_up_s", 0.5)),
        )
        cfg = TrainConfig(
            train_id=str(train or opts.get("train", name)),
            params=params,
            start=float(opts.get("start_m", 300.0)),
            mode="ktcs",
            ato=bool(opts.get("ato", True)),
            driver_speed=kmh(float(opts.get("max_speed_kmh", 80.0))),
        )
        return cls(name, line, cfg, links["rails"], control)

    def _from_rails(self, obj: dict[str, Any]) -> None:
        if "code" not in obj:
            return
        wire, tc = obj["code"], obj.get("tc")
        fields = _code_fields(wire)
        if fields is None or tc not in self.tcs:
            if wire is not None:
                self.note("bad_code", f"code {wire!r} for {tc!r} not understood: stop")
            self.code, self.code_tc = None, tc  # fail-safe: see `_code_now`
            return
        speed_kmh, gradient, distance = fields
        circuit = self.tcs[tc]  # up direction: the code counts from the entry end
        self.code = TrackCode.read(circuit.from_m, circuit.to_m, kmh(speed_kmh), gradient, distance)
        self.code_tc = tc

    def _code_now(self) -> TrackCode:
        if self.code is None or not self.rails.connected:
            return TrackCode.stop_here(self.endpoint.dynamics.state.position)
        return self.code

    def _position(self) -> dict[str, float]:
        head = self.endpoint.dynamics.state.position
        return {"head": head, "tail": head - self.config.params.length}

    def _sense(self, now: float) -> CycleInputs:
        """The cycle's inputs: the code under the antenna, the driver's EB release (once)."""
        release, self.release = self.release, False
        return CycleInputs(code=self._code_now(), release_eb=release)

    def _cycled(self, now: float, out: CycleOutputs | None) -> None:
        if out is None:
            return
        self.last = out
        for e in out.events:
            self.note(e.kind, e.text)
        self.rails.send({"position": self._position()})

    async def tasks(self) -> list[asyncio.Task[None]]:
        self.rails.send({"position": self._position()})
        self.drive(self.endpoint, self._cycled, origin=self.loop.time())
        self.poke()
        return [asyncio.ensure_future(self.rails.run())]

    def status(self) -> dict[str, Any]:
        s = self.endpoint.dynamics.state
        verdict = self.last.verdict if self.last is not None else None
        return {
            **super().status(),
            "train": self.config.train_id,
            **self._position(),
            "speed_kmh": round(s.speed * 3.6, 2),
            "code_tc": self.code_tc,
            "code": None
            if self.code is None
            else [
                round(self.code.speed * 3.6, 1),
                self.code.gradient,
                self.code.target_point,
            ],  # fmt: skip
            "status": None if verdict is None else str(verdict.status),
            "target_point": None if self.last is None else self.last.target_point,
        }

    async def command(self, obj: dict[str, Any]) -> dict[str, Any]:
        if obj.get("cmd") == "release_eb":
            self.release = True
            return {"ok": True}
        if obj.get("cmd") == "speed_distance":  # for the CTC console's speed-distance panel
            sd = endpoint_speed_distance(self.config.train_id, self.endpoint)
            return {"ok": True, "data": sd.to_json()}
        return await super().command(obj)
