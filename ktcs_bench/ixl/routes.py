"""Route state: what a route holds locked, and its life from setting to sequential release.

IDLE -> SETTING (locked, points being thrown) -> SET (every point detected; the signal may clear)
-> ENTERED (the entry section was occupied after the signal had cleared; sections release one by
one behind a train that runs through them in sequence, see `passed`) -> IDLE. A cancel goes
SETTING/SET -> IDLE at once when nothing approaches a signal that has shown proceed, else ->
CANCELLING (approach locked) -> IDLE when the timed release expires; a cancel of an ENTERED route
whose track circuits are all clear time-releases what it still holds.

Each route keeps its own set of held track circuits and points: the interlocking's locking is the
union of these sets, so "no element held twice" (SPEC §6.2 invariant 1) is checkable directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from ktcs_bench.station.model import Route


class RouteStatus(Enum):
    IDLE = "idle"
    SETTING = "setting"
    SET = "set"
    ENTERED = "entered"
    CANCELLING = "cancelling"


WHOLE = (RouteStatus.SETTING, RouteStatus.SET, RouteStatus.CANCELLING)


@dataclass
class RouteState:
    route: Route
    status: RouteStatus = RouteStatus.IDLE
    held_tcs: set[str] = field(default_factory=set)
    held_points: set[str] = field(default_factory=set)
    cleared_once: bool = False  # the entry signal has shown proceed since the route was set
    next_section: int = 0  # the first section not yet released
    # section k was occupied in a train's sequence: it went occupied while the track before it
    # (section k-1, or the approach for k = 0) was already occupied, not in the same report
    passed: list[bool] = field(default_factory=list)
    approach_left: bool = False  # the approach cleared while section 0 was occupied (passed)
    release_at: float | None = None  # approach-locking timed release
    overlap_at: float | None = None  # overlap timed release
    overlap_held: bool = False
    overlap_ceded: bool = False  # the overlap is held by the onward route from our exit signal

    @property
    def whole(self) -> bool:
        """Locked as a whole (not yet entered by a train)."""
        return self.status in WHOLE

    @property
    def holds_anything(self) -> bool:
        return bool(self.held_tcs or self.held_points)

    def lock(self) -> None:
        r = self.route
        self.status = RouteStatus.SETTING
        self.held_tcs = set(r.all_track_circuits)
        self.held_points = {s.point for s in r.all_points}
        self.cleared_once = False
        self.next_section = 0
        self.passed = [False] * len(r.release_sections)
        self.approach_left = False
        self.release_at = None
        self.overlap_at = None
        self.overlap_held = bool(r.overlap_track_circuits or r.overlap_points)
        self.overlap_ceded = False

    @property
    def overlap_elements(self) -> set[str]:
        return set(self.route.overlap_track_circuits) | {s.point for s in self.route.overlap_points}

    def cede_overlap(self, elements: set[str]) -> None:
        """Hand overlap elements to the onward route (a train will run through)."""
        self.held_tcs -= elements
        self.held_points -= elements
        self.overlap_held = False
        self.overlap_at = None
        self.overlap_ceded = True

    def take_back_overlap(self) -> None:
        self.held_tcs |= set(self.route.overlap_track_circuits)
        self.held_points |= {s.point for s in self.route.overlap_points}
        self.overlap_held = True
        self.overlap_ceded = False

    def release_all(self) -> None:
        self.status = RouteStatus.IDLE
        self.held_tcs.clear()
        self.held_points.clear()
        self.release_at = None
        self.overlap_at = None
        self.overlap_held = False
        self.overlap_ceded = False

    def release_section(self, index: int, points_in: dict[str, tuple[str, ...]]) -> None:
        """Release section `index` and the route points lying in its track circuits."""
        tcs = set(self.route.release_sections[index])
        self.held_tcs -= tcs
        for s in self.route.points:
            if set(points_in[s.point]) & tcs:
                self.held_points.discard(s.point)

    def release_overlap(self) -> None:
        self.held_tcs -= set(self.route.overlap_track_circuits)
        self.held_points -= {s.point for s in self.route.overlap_points}
        self.overlap_held = False
        self.overlap_at = None
