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
and the wayside ATC see the same line. A train runs up (rising chainage) or down: the onboard
keeps one coordinate, the distance run in its own direction, and the process maps the line into
it (`train.frame.Frame`: for a down train mirrored, a rise up a fall down, each code's track
circuit entered by its upper end) and each position it reports back to chainage (a down train's
head is its lower end). Orders and status speak chainage.

A train of the lab's timetable (`train: ID` with a lab-level `timetable:`) runs its entry
(`timetable_run`): its train data, its platform stops for the ATO (with precision-stop markers
before each mark), the station track it uses at each, and when it comes onto the line -- at
`enters.at_s` of its own time (0 at its start), 50 m short of the far end of its entry track
circuit, or standing at its first stop -- and only once the track circuits its body takes there
are clear as the rails report them (`train.entry.EntryGate`: it logs `waiting for TC1851 clear to
enter` once, then `entered`). Until then it is not on the rails. Its status carries
what it is doing (`state`), its arrivals (stop error on the true position) and departures.

The rails move it by the point blades (SPEC §6.7) and say so: derailed, it reads no code any more
(stop here: it comes to a stand and stays); misrouted (off its booked track), it runs on the codes
of the track it is actually on until it stands, and is held there.

A train whose service is over (finished at its last stop, standing, no order or EB pending:
`TrainEndpoint.at_rest`) cycles once a second, not every 100 ms -- a design decision (a lab's
finished trains cost little); an order wakes it at once. Its status's `time_s` is the device's
clock, not its last cycle's.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.emulator.device import Device
from ktcs_bench.emulator.rails import Hello, Position, RailsClient
from ktcs_bench.errors import ConfigError, UsageError
from ktcs_bench.messages import (
    TRAIN,
    Answer,
    DataAnswer,
    Dispatch,
    Hold,
    JsonObject,
    Message,
    Refused,
    ReleaseEb,
    ResultAnswer,
    RunTo,
    SpeedDistance,
    TrainOrder,
)
from ktcs_bench.station.model import Direction, Line
from ktcs_bench.station.timetable import TimetableTrain
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import (
    CYCLE,
    CycleInputs,
    CycleOutputs,
    LineData,
    Station,
    TrackCode,
    TrainConfig,
    TrainEndpoint,
)
from ktcs_bench.train.entry import EntryGate, body_track_circuits
from ktcs_bench.train.frame import Frame
from ktcs_bench.train.speed_distance import endpoint_speed_distance
from ktcs_bench.train.units import kmh
from ktcs_bench.transport.endpoints import Endpoint


def line_frame(line: Line, direction: Direction = "up") -> Frame:
    """The line as a train running `direction` sees it."""
    return Frame(line.start_m, line.end_m, direction)


def train_line(line: Line, frame: Frame | None = None) -> LineData:
    """The onboard view of a reference line in the train's `frame` (default: up): tags every
    `tag_spacing_m`, gradients, speed limits."""
    frame = frame or line_frame(line)
    tags = []
    x = line.start_m
    while x <= line.end_m:
        tags.append(x)
        x += line.tag_spacing_m
    gradient = frame.gradient((g.from_m, g.to_m, g.permille) for g in line.gradients)
    restrictions = frame.restrictions((s.from_m, s.to_m, kmh(s.kmh)) for s in line.speed_limits)
    return LineData(line.end_m, frame.tags(tags), gradient, restrictions, [])


PSM_M = (50.0, 20.0, 5.0)
"""Precision-stop markers (seed 002 Table 1): tags this far before each platform stop mark."""
ENTRY_SHORT_M = 50.0
"""A train entering at a track circuit comes on with its front this far short of its far end (the
end it leaves by: the upper for an up train, the lower for a down one)."""
BRAKE_BUILD_UP_S = 0.5


@dataclass(frozen=True)
class TimetableRun:
    """What the train process makes of its timetable entry (`timetable_run`)."""

    config: TrainConfig
    line: LineData
    enter_s: float
    """Its own time (s from its start) at which it comes onto the line."""
    tracks: tuple[tuple[float, float, str], ...]
    """(from_m, to_m, track): the station track it uses where its stations' tracks lie."""
    frame: Frame
    """The line as it runs it (its direction): `config`, `line` and the stops are in it."""
    entry_tcs: tuple[str, ...] = ()
    """The track circuits its body takes where it comes onto the line: clear before it does."""


def track_at(tracks: tuple[tuple[float, float, str], ...], head: float, tail: float) -> str | None:
    """The station track a train is on: where its head is, else where its tail is (None: on
    the plain line, every track)."""
    track = next((t for lo, hi, t in tracks if lo <= head < hi), None)
    return track or next((t for lo, hi, t in tracks if lo < tail < hi), None)


def timetable_run(train: TimetableTrain, line: Line, brake_build_up: float) -> TimetableRun:
    """The onboard data and start of a timetable train (see the module docstring)."""
    d = train.data
    params = TrainParams(
        length=d.length_m,
        max_speed=kmh(d.max_speed_kmh),
        max_traction=kmh(d.traction_kmh_per_s),
        service_decel=kmh(d.service_brake_kmh_per_s),
        emergency_decel=kmh(d.emergency_brake_kmh_per_s),
        brake_build_up=brake_build_up,
    )
    frame = line_frame(line, train.direction)
    onboard = train_line(line, frame)
    marks = [frame.s(s.stop_m) for s in train.stops]
    onboard.tags = sorted({*onboard.tags, *(m - back for m in marks for back in PSM_M)})
    onboard.stations = [
        Station(str(s.station), mark, s.dwell_s, train.depart_s if i == 0 else 0.0)
        for i, (s, mark) in enumerate(zip(train.stops, marks, strict=True))
    ]
    tracks = []
    for s in train.stops:
        circuits = line.station(s.station).track_circuits
        tracks.append((min(t.from_m for t in circuits), max(t.to_m for t in circuits), s.track))
    if train.enters is not None:
        entry = next(t for t in line.all_track_circuits() if t.name == train.enters.track_circuit)
        start = frame.span(entry.from_m, entry.to_m)[1] - ENTRY_SHORT_M
    else:
        start = marks[0]
    cfg = TrainConfig(
        train_id=train.id,
        params=params,
        start=start,
        mode="ktcs",
        ato=True,
        driver_speed=params.max_speed,
        leaves_line=train.leaves_lab,
    )
    head, tail = frame.x(start), frame.x(start - params.length)
    track = track_at(tuple(tracks), head, tail) or "1"
    # the body's upper end and its length: the same circuits whichever way it faces
    entry_tcs = body_track_circuits(
        line.all_track_circuits(), max(head, tail), params.length, track
    )
    return TimetableRun(cfg, onboard, train.enters_at_s, tuple(tracks), frame, entry_tcs)


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
    kind = kinds.TRAIN
    messages = TRAIN

    def __init__(
        self,
        name: str,
        line: Line,
        config: TrainConfig,
        rails: Endpoint,
        control: tuple[str, int] = ("127.0.0.1", 0),
        run: TimetableRun | None = None,
    ) -> None:
        super().__init__(name, control)
        self.line = line
        self.config = config if run is None else run.config
        config = self.config
        self.run_ = run
        self.tracks = () if run is None else run.tracks
        self.frame = line_frame(line) if run is None else run.frame  # placed by the lab: up
        # the first cycle one period after the start (or at its entry time), on the train's own
        # time (0 at the start); it is on the rails from its first cycle
        first = CYCLE if run is None else max(CYCLE, run.enter_s)
        onboard = train_line(line) if run is None else run.line
        self.endpoint = TrainEndpoint(
            config, onboard, sense=self._sense, first=first, chainage=self.frame.x
        )
        # a timetable train's entry waits for its entry track clear (a train the lab file puts
        # on the line stands there at once)
        self.gate = None if run is None else EntryGate(self.endpoint, first, run.entry_tcs)
        self.tcs = {t.name: t for t in line.all_track_circuits()}
        self.code: TrackCode | None = None
        self.code_tc: str | None = None
        hello = Hello(role=kinds.TRAIN, name=name, train=config.train_id)  # its kind names its key
        self.rails = RailsClient(rails, hello, self._from_rails, on_lost=self._rails_lost)
        self._sent_position: Position | None = None  # the last position told the rails
        self.last: Any = None
        self.release = False
        self.origin: float | None = None  # the device clock's reading at the train's start
        self.derailed: str | None = None  # the point ("18 31") the rails derailed it at
        self.actual_track: str | None = None  # the track it is on, once misrouted

    @classmethod
    def from_args(
        cls, name: str, lab: Any, line: Line, links: dict[str, Endpoint], train: str | None,
        control: tuple[str, int],
    ) -> TrainDevice:  # fmt: skip
        spec = lab.devices.get(name)
        opts = dict(spec.options) if spec is not None else {}
        if kinds.RAILS not in links:
            raise UsageError(
                "emulator train needs --link rails=tcp://HOST:PORT (the track circuits)"
            )
        train_id = str(train or opts.get(kinds.TRAIN, name))
        timetable = lab.load_timetable(line) if lab is not None else None
        if timetable is not None:
            try:
                entry = timetable.train(train_id)
            except KeyError:
                raise ConfigError(
                    timetable.file, "trains", f"no train {train_id!r} (device {name})"
                ) from None
            build_up = float(opts.get("brake_build_up_s", BRAKE_BUILD_UP_S))
            run = timetable_run(entry, line, build_up)
            return cls(name, line, run.config, links[kinds.RAILS], control, run)
        params = TrainParams(
            length=float(opts.get("length_m", 100.0)),
            max_speed=kmh(float(opts.get("max_speed_kmh", 80.0))),
            brake_build_up=float(opts.get("brake_build_up_s", BRAKE_BUILD_UP_S)),
        )
        cfg = TrainConfig(
            train_id=train_id,
            params=params,
            start=float(opts.get("start_m", 300.0)),
            mode="ktcs",
            ato=bool(opts.get("ato", True)),
            driver_speed=kmh(float(opts.get("max_speed_kmh", 80.0))),
        )
        return cls(name, line, cfg, links[kinds.RAILS], control)

    def _from_rails(self, obj: JsonObject) -> None:
        occupancy = obj.get("occupancy")
        if isinstance(occupancy, dict) and self.gate is not None and not self.gate.entered:
            self.gate.rails({k: bool(v) for k, v in occupancy.items()}, "full" in obj)
            self.poke()  # its entry may be clear now
        if "derailed" in obj and self.derailed is None:
            self.derailed = str(obj["derailed"])
            self.note("rails", f"derailed at point {self.derailed}: stops and stays")
        misrouted = obj.get("misrouted")
        if isinstance(misrouted, dict) and self.actual_track is None:
            self.actual_track = str(misrouted.get("track"))
            self.note("rails", f"misrouted onto track {self.actual_track}: stops at its next "
                      "stop code and stays")  # fmt: skip
        if "code" not in obj:
            return
        wire, tc = obj["code"], obj.get("tc")
        fields = _code_fields(wire)
        if fields is None or not isinstance(tc, str) or tc not in self.tcs:
            if wire is not None:
                self.note("bad_code", f"code {wire!r} for {tc!r} not understood: stop")
            # fail-safe: see `_code_now`
            self.code, self.code_tc = None, tc if isinstance(tc, str) else None
            return
        speed_kmh, gradient, distance = fields
        circuit = self.tcs[tc]  # the code counts from the end the train enters by
        self.code = self.frame.code(
            circuit.from_m, circuit.to_m, kmh(speed_kmh), gradient, distance
        )
        self.code_tc = tc

    def _rails_lost(self) -> None:
        if self.gate is not None:
            self.gate.rails_lost()

    def _code_now(self) -> TrackCode:
        if self.code is None or not self.rails.connected or self.derailed is not None:
            return TrackCode.stop_here(self.endpoint.dynamics.state.position)
        return self.code

    def _position(self) -> Position:
        """Where the train is on the rails, in chainage (its head leads in its direction)."""
        s = self.endpoint.dynamics.state.position
        length = self.config.params.length
        if self.endpoint.left:  # off the end of the line: on no track circuit of the lab
            s = self.line.end_m + 1.0 + length
        head, tail = self.frame.x(s), self.frame.x(s - length)
        out: Position = {"head": head, "tail": tail}
        if self.endpoint.left:
            return out
        track = track_at(self.tracks, head, tail)
        if track is not None:
            out["track"] = track
        return out

    @property
    def on_line(self) -> bool:
        """It has come onto the line (its first cycle has run)."""
        return self.endpoint.cycles > 0

    def _sense(self, now: float) -> CycleInputs:
        """The cycle's inputs: the code under the antenna, the driver's EB release (once)."""
        release, self.release = self.release, False
        ep = self.endpoint
        standing = ep.dynamics.state.speed <= 0.0
        if self.actual_track is not None and standing and not ep.held and self.config.ato:
            self.note("rails", f"misrouted: held where it stands ({ep.hold(now)})")
        return CycleInputs(code=self._code_now(), release_eb=release)

    def _cycled(self, now: float, out: CycleOutputs | None) -> None:
        for e in self.gate.take_events() if self.gate is not None else []:
            self.note(e.kind, e.text)
        if out is None:
            return
        self.last = out
        for e in out.events:
            self.note(e.kind, e.text)
        position = self._position()
        if position != self._sent_position or not self.rails.connected:
            # a train standing where it stood tells the rails nothing new (the rails change
            # nothing for it); a reconnected client says its last position again itself
            self.rails.send({"position": position})
            self._sent_position = position

    async def tasks(self) -> list[asyncio.Task[None]]:
        if self.run_ is None:  # a train put on the line by the lab file stands there at once
            self.rails.send({"position": self._position()})
        self.origin = self.now()  # the train's own time counts from here (the timetable's 0)
        self.drive(self.endpoint if self.gate is None else self.gate, self._cycled,
                   origin=self.origin)  # fmt: skip
        self.poke()
        return [asyncio.ensure_future(self.rails.run())]

    def status(self) -> dict[str, Any]:
        s = self.endpoint.dynamics.state
        verdict = self.last.verdict if self.last is not None else None
        ep = self.endpoint
        now = 0.0 if self.origin is None else self.now() - self.origin
        at = self._chainage
        return {
            **super().status(),
            kinds.TRAIN: self.config.train_id,
            "direction": self.frame.sense,
            **self._position(),
            **({} if self.actual_track is None else {"track": self.actual_track}),  # where it is
            "time_s": round(now, 1),
            "state": ep.service_state(now) if self.on_line else "waiting",
            "held": ep.held,
            "stop_at": at(ep.commanded_stop),
            "enters_s": None if self.run_ is None else self.run_.enter_s,
            # the track circuits it waits for clear to come onto the line
            "waiting_for": self.gate.blocking()
            if self.gate and self.gate.waiting and not self.gate.entered
            else [],
            "next_stop": None if ep.next_stop is None else ep.next_stop.name,
            "arrivals": [
                {
                    "station": a.station,
                    "stop_m": round(self.frame.x(a.stop_mark), 3),
                    "head_m": round(self.frame.x(a.head), 3),
                    "error_m": round(a.error, 3),
                    "time_s": round(a.time, 1),
                }
                for a in ep.arrivals
            ],  # fmt: skip
            "departures": [
                {"station": d.station, "time_s": round(d.time, 1)} for d in ep.departures
            ],
            "speed_kmh": round(s.speed * 3.6, 2),
            "code_tc": self.code_tc,
            "code": None
            if self.code is None
            else [
                round(self.code.speed * 3.6, 1),
                self.code.gradient,
                at(self.code.target_point),
            ],  # fmt: skip
            "status": None if verdict is None else verdict.status.value,
            "emergency_brakes": ep.eb_count,
            "derailed": self.derailed,
            "misrouted_onto": self.actual_track,
            "target_point": None if self.last is None else at(self.last.target_point),
            "limits_kmh": self._limits_kmh(),
        }

    def _limits_kmh(self) -> dict[str, float] | None:
        """The supervised speeds at the front -- EBI, SBI, warning, permitted, MRSP -- km/h,
        finite ones only: the curves a report draws beside the actual speed (None: off the
        line, nothing supervised yet)."""
        if not self.on_line or self.last is None:
            return None
        speeds = self.endpoint.limit_speeds()
        return {k: round(v * 3.6, 1) for k, v in speeds.items() if k != "ebd" and math.isfinite(v)}

    def _chainage(self, s: float | None) -> float | None:
        """A place the onboard names (None or infinite: none) as chainage, for people."""
        return s if s is None or not math.isfinite(s) else self.frame.x(s)

    def _order(self, order: TrainOrder) -> Answer:
        """The operator's orders to the ATO: hold, dispatch [now], run_to AT (m on the line)."""
        now = 0.0 if self.origin is None else self.now() - self.origin
        ep = self.endpoint
        try:
            match order:
                case Hold():
                    text = ep.hold(now)
                case Dispatch(now=at_once):
                    text = ep.dispatch(now, at_once=at_once)
                case RunTo(at=at):
                    text = ep.run_to(now, self.frame.s(at))
        except UsageError as exc:
            return Refused(error=str(exc))
        self.note(order.cmd(), text)
        return ResultAnswer(result=text)

    async def handle(self, message: Message) -> Answer:
        match message:
            case ReleaseEb():
                self.release = True
                return Answer()
            case Hold() | Dispatch() | RunTo():
                return self._order(message)
            case SpeedDistance():  # for the CTC console's speed-distance panel
                sd = endpoint_speed_distance(self.config.train_id, self.endpoint)
                return DataAnswer(data=sd.to_json())
        return await super().handle(message)
