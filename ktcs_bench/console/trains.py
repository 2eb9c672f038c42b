"""The trains for the console: the provider interface and its in-process implementation.

`TrainSource` is what the console asks: which trains there are, where each stands on the line
(`TrainPosition`, drawn on the diagram), and for one train its curves and actual point
(`train.speed_distance.SpeedDistance`). `EndpointTrains` computes them from in-process
`TrainEndpoint` objects; the CTC process has one over train processes (`emulator.ctc.RemoteTrains`,
which reads each train's status with `position_from_status`): an implementation only has to give
the three methods.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypedDict

from ktcs_bench.train.endpoint import TrainEndpoint
from ktcs_bench.train.speed_distance import SpeedDistance, endpoint_speed_distance
from ktcs_bench.train.units import to_kmh


class TrainPositionJson(TypedDict):
    """A train's position as the page draws it (m and km/h to one decimal)."""

    train: str
    head_m: float
    tail_m: float
    speed_kmh: float
    track: str | None
    state: str | None


@dataclass(frozen=True)
class TrainPosition:
    """Where a train stands, for the diagram: its front and rear (m, up the line), the station
    track it uses there (None: the main line, or not known), its speed and service state."""

    train: str
    head_m: float
    tail_m: float
    speed_kmh: float
    track: str | None = None
    state: str | None = None

    def to_json(self) -> TrainPositionJson:
        return TrainPositionJson(
            train=self.train,
            head_m=round(self.head_m, 1),
            tail_m=round(self.tail_m, 1),
            speed_kmh=round(self.speed_kmh, 1),
            track=self.track,
            state=self.state,
        )


OFF_LINE_STATES = ("waiting", "left")
"""A train device's states when it is on no track of the line (not come on yet, gone off it)."""


def _number(v: object) -> float | None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None  # type: ignore[arg-type]


def position_from_status(train: str, status: Mapping[str, Any]) -> TrainPosition | None:
    """A train device's status (`emulator.train.TrainDevice.status`) as a position; None when
    it is not on the line or the status does not say where it is."""
    head, tail = _number(status.get("head")), _number(status.get("tail"))
    state = status.get("state")
    if head is None or tail is None or state in OFF_LINE_STATES:
        return None
    track = status.get("track")
    return TrainPosition(
        train,
        head,
        tail,
        _number(status.get("speed_kmh")) or 0.0,
        str(track) if track is not None else None,
        str(state) if state is not None else None,
    )


class TrainSource(Protocol):
    def train_ids(self) -> list[str]: ...

    async def positions(self) -> list[TrainPosition]: ...

    async def speed_distance(self, train: str) -> SpeedDistance | None: ...


class EndpointTrains:
    """A TrainSource over in-process endpoints: a mapping train id -> TrainEndpoint, or a callable
    returning one (so trains may come and go)."""

    def __init__(
        self, trains: Mapping[str, TrainEndpoint] | Callable[[], Mapping[str, TrainEndpoint]]
    ) -> None:
        self._trains = trains

    def _all(self) -> Mapping[str, TrainEndpoint]:
        return self._trains() if callable(self._trains) else self._trains

    def train_ids(self) -> list[str]:
        return sorted(self._all())

    async def positions(self) -> list[TrainPosition]:
        out = []
        for train, ep in sorted(self._all().items()):
            head = ep.state.position
            tail = head - ep.cfg.params.length
            out.append(TrainPosition(train, head, tail, to_kmh(ep.state.speed)))
        return out

    async def speed_distance(self, train: str) -> SpeedDistance | None:
        ep = self._all().get(train)
        return None if ep is None else endpoint_speed_distance(train, ep)
