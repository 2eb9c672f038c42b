"""The wayside resource manager of seed 000 §3.3, as a sans-I/O object.

Owns which train holds which stretch of line. A train asks for resources up to a location; the
manager locks, in the running direction, every free resource from the train's tail onwards until
it meets one held by another train, the requested end, or a point not yet detected in the position
the route needs — that point is commanded, and the authority extends when its detection arrives
(`point_detected`). Resources wholly behind a train's tail are released. Outputs are returned
values (grants, point commands, events); the TCP adapter later only serialises them.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Resource:
    id: str
    start: float
    end: float
    point: str | None = None
    """A point inside this resource, if any."""
    required: str = "normal"
    """Position the route needs that point in."""


@dataclass(frozen=True)
class PointCommand:
    point: str
    position: str
    time: float


@dataclass(frozen=True)
class Grant:
    train_id: str
    authority_end: float
    locked: tuple[str, ...]
    commands: tuple[PointCommand, ...] = ()


@dataclass
class ResourceManager:
    resources: list[Resource]
    point_positions: dict[str, str] = field(default_factory=dict)
    """Detected position of each point ("normal", "reverse", or "moving")."""
    holder: dict[str, str] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.resources.sort(key=lambda r: r.start)
        for r in self.resources:
            if r.point is not None:
                self.point_positions.setdefault(r.point, "normal")

    def request(self, train_id: str, tail: float, up_to: float, now: float) -> Grant:
        """dRequestResource for one train; returns what is locked and the authority end."""
        self._release_behind(train_id, tail, now)
        locked: list[str] = []
        commands: list[PointCommand] = []
        authority = tail
        for r in self.resources:
            if r.end <= tail:
                continue
            if r.start >= up_to:
                break
            owner = self.holder.get(r.id)
            if owner is not None and owner != train_id:
                break
            if owner is None:
                self.holder[r.id] = train_id
                self.events.append((now, f"{r.id} locked by {train_id}"))
            locked.append(r.id)
            if r.point is not None and self.point_positions.get(r.point) != r.required:
                if self.point_positions.get(r.point) != "moving":
                    self.point_positions[r.point] = "moving"
                    commands.append(PointCommand(r.point, r.required, now))
                    self.events.append((now, f"point {r.point} commanded {r.required}"))
                authority = r.start
                break
            authority = r.end
        return Grant(train_id, min(authority, up_to), tuple(locked), tuple(commands))

    def point_detected(self, point: str, position: str, now: float) -> None:
        """Detection from the trackside: the next request extends past this point if it fits."""
        self.point_positions[point] = position
        self.events.append((now, f"point {point} detected {position}"))

    def _release_behind(self, train_id: str, tail: float, now: float) -> None:
        for r in self.resources:
            if r.end <= tail and self.holder.get(r.id) == train_id:
                del self.holder[r.id]
                self.events.append((now, f"{r.id} released by {train_id}"))
