"""Train position from tags and the tachometer (seed 000 §3.2).

Owns the onboard position: the last read tag id (LRTI) and the tachometer offset since it, the
head = tag location + offset, the tail = head − length, and a confidence interval that grows with
the offset (tacho error) on top of the tag reading window. A tag expected but not read within the
tolerance is reported as a missed tag (the ATP trips on it). Sans-I/O: the caller feeds the true
travel each cycle (the plant), the estimator decides what the reader and tacho would have seen.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

from ktcs_bench.errors import UsageError


@dataclass(frozen=True)
class Position:
    lrti: int
    """Last read tag id (1-based), 0 before any tag."""
    offset: float
    """Tachometer distance since that tag, m."""
    head: float
    tail: float
    uncertainty: float
    """Half-width of the confidence interval, m."""

    @property
    def max_safe_front(self) -> float:
        return self.head + self.uncertainty

    @property
    def min_safe_rear(self) -> float:
        return self.tail - self.uncertainty


@dataclass
class PositionEstimator:
    tags: list[float]
    """Tag locations along the line, m, increasing; tag id = index + 1."""
    length: float
    tacho_error: float = 0.01
    """Relative tachometer error (bias applied to measured travel, and the CI growth rate)."""
    read_window: float = 1.0
    """Tag reading uncertainty, m."""
    missed_tags: frozenset[int] = frozenset()
    """Tag ids the reader will not read (fault injection)."""
    lrti: int = 0
    offset: float = 0.0
    base: float = 0.0
    missed: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        if any(b <= a for a, b in zip(self.tags, self.tags[1:], strict=False)):
            raise UsageError("tag locations must increase strictly")

    def start(self, true_head: float) -> Position:
        """Initialise at a known location (e.g. from the train's last tag at start-up)."""
        i = bisect.bisect_right(self.tags, true_head) - 1
        if i >= 0:
            self.lrti, self.base, self.offset = i + 1, self.tags[i], true_head - self.tags[i]
        else:
            self.lrti, self.base, self.offset = 0, true_head, 0.0
        return self.position()

    def advance(self, true_from: float, true_to: float) -> tuple[Position, list[int]]:
        """The train's true front moved from → to; returns the estimate and newly missed tags."""
        self.offset += (true_to - true_from) * (1.0 + self.tacho_error)
        newly_missed: list[int] = []
        lo = bisect.bisect_right(self.tags, true_from)
        hi = bisect.bisect_right(self.tags, true_to)
        for k in range(lo, hi):
            tag_id = k + 1
            if tag_id in self.missed_tags:
                continue
            self.lrti, self.base, self.offset = tag_id, self.tags[k], true_to - self.tags[k]
        # a tag is missed when the odometry says we are past the next one beyond tolerance
        nxt = self.lrti  # index of next tag
        if nxt < len(self.tags):
            expected_at = self.tags[nxt] - self.base
            tol = self.read_window + self.tacho_error * expected_at + 2.0
            if self.offset > expected_at + tol and (nxt + 1) not in self.missed:
                self.missed.append(nxt + 1)
                newly_missed.append(nxt + 1)
        return self.position(), newly_missed

    def position(self) -> Position:
        head = self.base + self.offset
        unc = self.read_window + self.tacho_error * self.offset
        return Position(self.lrti, self.offset, head, head - self.length, unc)


CALIBRATION_SPAN = 50.0
"""Tags at least this far apart calibrate the tachometer, m (a shorter span, e.g. between the
precision-stop markers, measures its scale too coarsely to carry it on)."""


@dataclass
class TachoScale:
    """The tachometer's scale measured between successive tags (the wheel calibration an onboard
    makes at each balise): the tacho's travel from one tag to the next over their distance on the
    line. `head(pos)` is the position with the travel since the last tag divided by it -- for a
    stop at a place with no tag just before it (a commanded stop point), where the tacho's bias
    would otherwise put the front off by up to its error times the distance from the last tag.

    Fed each cycle's `Position`; the travel in the cycle that reads a tag is taken as the cycle
    before's (the speed hardly changes in 100 ms). A span counts from a tag read on the move (at
    the start the offset is where the train was put, not what the tacho measured)."""

    tags: list[float]
    scale: float = 1.0
    _prev: Position | None = None
    _step: float = 0.0
    _read: bool = False

    def update(self, pos: Position) -> None:
        prev, self._prev = self._prev, pos
        if prev is None:
            return
        if pos.lrti == prev.lrti:
            self._step = pos.offset - prev.offset
            return
        if pos.lrti == prev.lrti + 1 and self._read and self._step > 0.0:
            span = self.tags[pos.lrti - 1] - self.tags[prev.lrti - 1]
            measured = prev.offset + self._step - pos.offset
            if span >= CALIBRATION_SPAN and measured > 0.0:
                self.scale = measured / span
        self._step, self._read = 0.0, pos.lrti > prev.lrti

    def head(self, pos: Position) -> float:
        """The front with the tacho's travel since the last tag corrected by its scale, m."""
        return pos.head - pos.offset + pos.offset / self.scale
