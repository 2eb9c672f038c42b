"""Speed–distance data for the console: the provider interface and its in-process implementation.

`TrainSource` is what the console asks: which trains there are, and for one train its curves and
actual point (`train.speed_distance.SpeedDistance`). `EndpointTrains` computes them from
in-process `TrainEndpoint` objects; the CTC process has one over train processes
(`emulator.ctc.RemoteTrains`): an implementation only has to give the two methods.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

from ktcs_bench.train.endpoint import TrainEndpoint
from ktcs_bench.train.speed_distance import SpeedDistance, endpoint_speed_distance


class TrainSource(Protocol):
    def train_ids(self) -> list[str]: ...

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

    async def speed_distance(self, train: str) -> SpeedDistance | None:
        ep = self._all().get(train)
        return None if ep is None else endpoint_speed_distance(train, ep)
