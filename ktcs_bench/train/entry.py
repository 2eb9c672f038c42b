"""When a timetable train comes onto the line (issue 23 §2, SPEC §6.7): at its entry time, and
only once every track circuit its body would occupy there is clear as the rails report it -- a
train never appears on top of another standing at the lab's edge. Until then it is not on the
line.

`EntryGate` is sans-I/O and wraps the train's endpoint as the one core its process drives (the
`ktcs_bench.timed` shape): fed the rails' occupancy (`rails`, `rails_lost`), it holds the
endpoint's first cycle back until the entry is clear, and says so once (`waiting for TC1851
clear to enter`), then `entered`. Its deadline is the entry time while the train may enter, none
while it waits (the next occupancy report moves it: the process pokes its driver).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ktcs_bench.station.model import TrackCircuit
from ktcs_bench.train.endpoint import CycleOutputs, TrainEndpoint, TrainEvent


def body_track_circuits(
    circuits: Iterable[TrackCircuit], head_m: float, length_m: float, track: str
) -> tuple[str, ...]:
    """The track circuits a train's axles shunt with its front at `head_m` (up: its rear
    `length_m` behind) on `track` -- the track-circuit emulator's rule."""
    lo, hi = head_m - length_m, head_m
    return tuple(t.name for t in circuits if lo < t.to_m and hi > t.from_m and t.on_track(track))


@dataclass
class EntryGate:
    """A timetable train's entry (see the module docstring). `at_s`: its entry time on its own
    clock; `track_circuits`: those its body occupies where it enters."""

    endpoint: TrainEndpoint
    at_s: float
    track_circuits: tuple[str, ...]
    occupied: dict[str, bool] | None = None  # as the rails last reported; None: not known
    entered_at: float | None = None
    waiting: bool = False  # it was due and found its entry occupied (said once)

    def __post_init__(self) -> None:
        self.events: list[TrainEvent] = []

    @property
    def entered(self) -> bool:
        return self.entered_at is not None

    def rails(self, occupancy: Mapping[str, bool], full: bool) -> None:
        """The rails' report: every track circuit (`full`: on connecting), or the changes (of
        no use before a full report)."""
        if full:
            self.occupied = dict(occupancy)
        elif self.occupied is not None:
            self.occupied.update(occupancy)

    def rails_lost(self) -> None:
        """No report from the rails: the entry is not known to be clear."""
        self.occupied = None

    def blocking(self) -> list[str]:
        """The entry's track circuits not reported clear (all of them while nothing is known)."""
        if self.occupied is None:
            return list(self.track_circuits)
        return [t for t in self.track_circuits if self.occupied.get(t, True)]

    def next_deadline(self) -> float | None:
        if self.entered:
            return self.endpoint.next_deadline()
        if self.waiting and self.blocking():
            return None  # until the rails report the entry clear
        return self.at_s

    def handle_timer(self, now: float) -> CycleOutputs | None:
        if self.entered_at is None:
            if now < self.at_s:
                return None
            blocking = self.blocking()
            if blocking:
                if not self.waiting:
                    self._event(now, f"waiting for {', '.join(blocking)} clear to enter")
                self.waiting = True
                return None
            self.entered_at = now
            self.endpoint.first = now  # its first cycle is its entry
            self._event(now, "entered")
        return self.endpoint.handle_timer(now)

    def take_events(self) -> list[TrainEvent]:
        events, self.events = self.events, []
        return events

    def _event(self, now: float, text: str) -> None:
        self.events.append(TrainEvent(now, self.endpoint.cfg.train_id, "entry", text))
