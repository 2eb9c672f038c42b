"""Breadth-first search over every input order of one station's world (`world.World`) within a
bound: the real interlocking core, branched by copying, its states hashed canonically. BFS gives
the shortest input sequence to each state, so a violation comes with the shortest way to it.

Compositional (SPEC §13): a station is searched alone, its linked intervals' far ends played by
an environment that may say anything the permission protocol allows; a line costs the sum of its
stations.
"""

from __future__ import annotations

import hashlib
import marshal
import time
from collections import deque
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from ktcs_bench.errors import UsageError
from ktcs_bench.station.geometry import LineGeometry
from ktcs_bench.station.model import Line
from ktcs_bench.verify.world import Budget, Copier, Step, World, spawn_places


@dataclass(frozen=True)
class Bound:
    """How far the search goes: inputs per sequence (`depth`), and at most so many route
    requests, point commands, operator moves (a mode change, a signal held at stop or released),
    trains, faults and neighbour moves in one sequence.
    Cancels, timers, train moves, repairs, links coming back and the neighbour reading what was
    said are limited by `depth` alone."""

    depth: int = 40
    requests: int = 0
    points: int = 0
    modes: int = 0
    trains: int = 0
    faults: int = 0
    env: int = 0
    states: int = 200_000  # a cap per station: reached, the search says it stopped short

    @classmethod
    def parse(cls, text: str) -> Bound:
        """`depth=8,requests=2,...` over the defaults; UsageError on anything else."""
        values: dict[str, int] = {}
        known = {f.name for f in fields(cls)}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, sep, value = part.partition("=")
            if not sep or key not in known:
                raise UsageError(f"bad --bound item {part!r} (keys: {', '.join(sorted(known))})")
            try:
                values[key] = int(value)
            except ValueError:
                raise UsageError(f"bad --bound value {part!r}: not a whole number") from None
            if values[key] < 0:
                raise UsageError(f"bad --bound value {part!r}: negative")
        return cls(**values)

    @classmethod
    def parse_all(cls, text: str) -> list[Bound]:
        """Campaigns separated by `;` (each `key=value,...`); empty: `DEFAULT_CAMPAIGNS`."""
        if not text.strip():
            return list(DEFAULT_CAMPAIGNS)
        return [cls.parse(part) for part in text.split(";") if part.strip()]

    def budget(self) -> Budget:
        return Budget(self.requests, self.points, self.modes, self.trains, self.faults, self.env)

    def text(self) -> str:
        return ",".join(f"{k}={v}" for k, v in asdict(self).items())


DEFAULT_CAMPAIGNS: tuple[Bound, ...] = (
    Bound(requests=2),
    Bound(requests=1, trains=1),
    Bound(requests=1, faults=1),
    Bound(requests=1, env=2),
    Bound(requests=1, modes=1),
    Bound(points=1, trains=1),
)
"""The default bound: one search per budget (each exhaustive within it), not their product --
the reference line verifies within a minute (docs/verification.md says what that leaves out)."""


@dataclass
class Violation:
    station: int
    what: list[str]
    steps: list[Step]

    def as_dict(self) -> dict[str, Any]:
        return {"station": self.station, "what": self.what, "steps": [list(s) for s in self.steps]}


@dataclass
class StationResult:
    station: int
    states: int = 0
    transitions: int = 0
    seconds: float = 0.0
    depth_reached: int = 0
    complete: bool = True  # every state within the bound explored (no cap hit)
    violations: list[Violation] = field(default_factory=list)

    @property
    def per_second(self) -> float:
        return self.states / self.seconds if self.seconds > 0 else 0.0

    def as_dict(self) -> dict[str, Any]:
        return {
            "states": self.states, "transitions": self.transitions,
            "seconds": round(self.seconds, 3), "states_per_second": round(self.per_second),
            "depth_reached": self.depth_reached, "complete": self.complete,
            "violations": len(self.violations),
        }  # fmt: skip


def digest(data: bytes) -> bytes:
    return hashlib.blake2b(data, digest_size=16).digest()


def _key(world: World, static: frozenset[int]) -> bytes:
    """The canonical state as a short digest (kept per state: small, and cheap to compare)."""
    return digest(marshal.dumps(world.key(static), 2))  # version 2: no shared references


def start(line: Line, number: int, bound: Bound) -> World:
    world = World(line.view(number), LineGeometry(line), bound.budget())
    world.forget_logs()
    return world


def explore_station(
    line: Line, number: int, bound: Bound, *, max_violations: int = 1, canonical: bool = True
) -> StationResult:
    """BFS from the station's start state (center mode, links up, everything clear, the
    permissions as the line's default directions give them) to `bound.depth` inputs."""
    started = time.monotonic()
    result = StationResult(number)
    root = start(line, number, bound)
    copier = Copier(root)
    static = copier.static_ids
    spawns = spawn_places(root.view)
    bad = root.check()
    if bad:
        result.violations.append(Violation(number, bad, []))
        return result
    seen = {_key(root, static) if canonical else digest(copier.dump(root))}
    frontier: deque[tuple[bytes, tuple[Step, ...]]] = deque([(copier.dump(root), ())])
    while frontier:
        data, path = frontier.popleft()
        result.depth_reached = max(result.depth_reached, len(path))
        if len(path) >= bound.depth:
            continue
        parent = copier.load(data)
        steps = list(parent.steps(spawns))
        for i, step in enumerate(steps):
            nxt = parent if i == len(steps) - 1 else copier.load(data)
            nxt.apply(step)
            nxt.forget_logs()
            result.transitions += 1
            bad = nxt.check()
            if bad:
                result.violations.append(Violation(number, bad, [*path, step]))
                if len(result.violations) >= max_violations:
                    frontier.clear()
                    break
                continue
            key = _key(nxt, static) if canonical else digest(copier.dump(nxt))
            if key in seen:
                continue
            dumped = copier.dump(nxt)
            seen.add(key)
            if len(seen) >= bound.states:
                result.complete = False
                frontier.clear()
                break
            frontier.append((dumped, (*path, step)))
    result.states = len(seen)
    result.seconds = time.monotonic() - started
    return result


def replay(line: Line, number: int, bound: Bound, steps: list[Step]) -> list[str]:
    """Feed `steps` to a fresh world; the invariants broken at the end (a counterexample
    replayed on the real core)."""
    world = start(line, number, bound)
    bad: list[str] = []
    for step in steps:
        world.apply(step)
        bad = world.check()
    return bad
