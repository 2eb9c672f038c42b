"""The train describer: which train is on which track circuits, from occupancy alone (pure).

A CTC sees track circuits, not trains. As a real train describer does, this one gives each train
its number when it comes onto the line and steps the number from berth to berth as the track
circuits ahead of it occupy and those behind it clear:

* a train is **identified** when a track circuit occupies that no described train explains, and
  it is where the next train of the timetable comes onto the line (`enters: track_circuit`) or
  stands at the start (its first stop's platform circuit);
* a train's head **steps** into a track circuit next to it (ahead, in its direction of travel)
  that is occupied and not another train's;
* its rear **clears**: track circuits of its footprint that report clear drop out of it;
* a train whose track circuits all clear is **lost** at its last berth (a flicker, a train
  running with its detection failed) and found again when that berth or the one ahead occupies --
  unless its last berth was at the end of the line: then it has **left** the lab.

After a CTC restart the trains already on the line are **picked up** (`pick_up`) from the first
whole picture: each run of occupied circuits no train explains (and not where the next train
comes onto the line: that one is identified as ever) is given the timetable train not yet seen
whose booked path covers it, the one the indications agree with best (the direction an
interval or a set route over it shows, the platform track its timetable uses there), the leading
run of a direction going to the earlier train of the timetable.

Unknown occupancy (a station whose link is down, or showing its fail-safe picture: ARS hands
that on as unknown) neither steps nor clears anything. Adjacency is
data: two track circuits are next to each other where one ends at the chainage the other begins
and they share a track (a plain-line circuit carries every track). No clock, no I/O: `update` takes
the occupancy and `now` and returns what happened.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Mapping
from dataclasses import dataclass, field

from ktcs_bench.station.model import Direction, Line, TrackCircuit
from ktcs_bench.station.timetable import Timetable, TimetableTrain

EPS_M = 1e-6


@dataclass(frozen=True, slots=True)
class DescriberEvent:
    time: float
    train: str | None
    kind: str  # identified, picked up, lost, found, left, unexplained
    track_circuit: str
    text: str


@dataclass
class DescribedTrain:
    """One train the describer follows. `footprint`: its occupied track circuits, rear first."""

    service: TimetableTrain
    footprint: list[str] = field(default_factory=list)
    berth: str = ""  # the head's track circuit (kept while the train is lost)
    identified_at: float = 0.0
    picked_up: bool = False  # found on the line at the CTC's start, not seen coming onto it

    @property
    def id(self) -> str:
        return self.service.id

    @property
    def direction(self) -> Direction:
        return self.service.direction

    @property
    def lost(self) -> bool:
        return not self.footprint


def _adjacent(a: TrackCircuit, b: TrackCircuit) -> bool:
    """`b` begins where `a` ends (rising chainage) and they share a track."""
    if abs(a.to_m - b.from_m) > EPS_M:
        return False
    return not a.tracks or not b.tracks or bool(set(a.tracks) & set(b.tracks))


def _neighbours(tcs: list[TrackCircuit]) -> dict[Direction, dict[str, tuple[str, ...]]]:
    """Each circuit's `_adjacent` ones ahead, up and down, in the order of `tcs`: only the
    circuits beginning (ending) about where it ends (begins) are looked at, found by bisection
    (a long line has hundreds of circuits; looking at every pair took a CTC's start)."""
    starts = sorted((t.from_m, i) for i, t in enumerate(tcs))
    ends = sorted((t.to_m, i) for i, t in enumerate(tcs))
    window = 2 * EPS_M  # wider than `_adjacent`'s: it decides

    def near(pairs: list[tuple[float, int]], at: float) -> list[int]:
        lo = bisect_left(pairs, (at - window, -1))
        hi = bisect_right(pairs, (at + window, len(tcs)))
        return sorted(i for _, i in pairs[lo:hi])

    up = {a.name: tuple(tcs[i].name for i in near(starts, a.to_m) if _adjacent(a, tcs[i]))
          for a in tcs}  # fmt: skip
    down = {b.name: tuple(tcs[i].name for i in near(ends, b.from_m) if _adjacent(tcs[i], b))
            for b in tcs}  # fmt: skip
    return {"up": up, "down": down}


class Describer:
    """Train numbers on the line's track circuits. See the module docstring."""

    def __init__(self, line: Line, timetable: Timetable) -> None:
        self.line = line
        self.circuits = {t.name: t for t in line.all_track_circuits()}
        self._ahead: dict[Direction, dict[str, tuple[str, ...]]] = _neighbours(
            list(self.circuits.values())
        )
        self.expected: list[TimetableTrain] = sorted(
            timetable.trains, key=lambda t: t.enters_at_s
        )  # not yet on the line, in the order they enter
        self.trains: dict[str, DescribedTrain] = {}
        self.gone: list[str] = []  # trains that left the lab
        self._paths: dict[str, set[str]] = {}
        self._unexplained: set[str] = set()

    def ahead(self, tc: str, direction: Direction) -> tuple[str, ...]:
        """The track circuits next to `tc` in `direction` of travel."""
        return self._ahead[direction].get(tc, ())

    def train_at(self, tc: str) -> DescribedTrain | None:
        for t in self.trains.values():
            if tc in t.footprint:
                return t
        return None

    def _order(self) -> list[DescribedTrain]:
        """Leading trains first, so a follower never takes the circuit its leader steps into."""

        def lead(t: DescribedTrain) -> float:
            tc = self.circuits[t.berth]
            return tc.from_m if t.direction == "up" else -tc.to_m

        return sorted(self.trains.values(), key=lead, reverse=True)

    def update(self, occupancy: Mapping[str, bool | None], now: float) -> list[DescriberEvent]:
        """Step the trains on `occupancy` (track circuit -> occupied; None or absent: unknown)."""
        events: list[DescriberEvent] = []
        owned = {tc for t in self.trains.values() for tc in t.footprint}
        for t in self._order():
            if t.lost:
                nxt = [t.berth] if occupancy.get(t.berth) is True and t.berth not in owned else []
                nxt = nxt or self._free_ahead(t.berth, t.direction, occupancy, owned)
                if not nxt:
                    continue
                t.footprint = [nxt[0]]
                t.berth = nxt[0]
                owned.add(nxt[0])
                events.append(
                    DescriberEvent(
                        now, t.id, "found", t.berth, f"train {t.id} found again at {t.berth}"
                    )
                )
            while True:  # the head steps on while the circuit ahead is occupied
                nxt = self._free_ahead(t.footprint[-1], t.direction, occupancy, owned)
                if not nxt or nxt[0] in t.footprint:
                    break
                t.footprint.append(nxt[0])
                owned.add(nxt[0])
            t.berth = t.footprint[-1]
            kept = [tc for tc in t.footprint if occupancy.get(tc) is not False]
            owned -= set(t.footprint) - set(kept)
            t.footprint = kept
            if t.lost:
                if self._at_edge(t.berth, t.direction):
                    del self.trains[t.id]
                    self.gone.append(t.id)
                    events.append(
                        DescriberEvent(
                            now, t.id, "left", t.berth, f"train {t.id} left the lab at {t.berth}"
                        )
                    )
                else:
                    events.append(
                        DescriberEvent(
                            now,
                            t.id,
                            "lost",
                            t.berth,
                            f"train {t.id} lost at {t.berth}: its track circuits report clear",
                        )
                    )
        for tc, occ in occupancy.items():
            if occ is not True:
                self._unexplained.discard(tc)
                continue
            if tc in owned:
                continue
            service = next((s for s in self.expected if s.appears_on == tc), None)
            if service is not None:
                self.expected.remove(service)
                self.trains[service.id] = DescribedTrain(service, [tc], tc, now)
                owned.add(tc)
                self._unexplained.discard(tc)
                events.append(
                    DescriberEvent(
                        now, service.id, "identified", tc, f"train {service.id} identified at {tc}"
                    )
                )
            elif tc not in self._unexplained:
                self._unexplained.add(tc)
                events.append(
                    DescriberEvent(
                        now, None, "unexplained", tc, f"{tc} occupied: no train described there"
                    )
                )
        return events

    def pick_up(
        self,
        occupancy: Mapping[str, bool | None],
        now: float,
        hints: Mapping[str, Direction] | None = None,
    ) -> list[DescriberEvent]:
        """Name the trains already on the line (see the module docstring): each run of occupied
        circuits no described train explains gets the best-fitting timetable train not yet seen.
        `hints`: the direction the indications show over a circuit (an interval's traffic
        direction, a set route's). A run no train's path covers stays unexplained."""
        hints = hints or {}
        owned = {tc for t in self.trains.values() for tc in t.footprint}
        runs = self._runs([tc for tc, occ in occupancy.items() if occ is True and tc not in owned])
        appears = {s.appears_on for s in self.expected}
        runs = [r for r in runs if not appears & set(r)]  # where a train appears: identified
        order = {s.id: i for i, s in enumerate(self.expected)}
        fits: list[dict[str, int]] = []  # per run: train -> how well it fits
        for run in runs:
            shown = {hints[tc] for tc in run if tc in hints}
            fit: dict[str, int] = {}
            for s in self.expected:
                if not set(run) <= self._path(s):
                    continue
                score = 2 if shown == {s.direction} else -2 if shown else 0
                fit[s.id] = score + any(self._on_booked_platform(s, tc) for tc in run)
            fits.append(fit)
        by_id = {s.id: s for s in self.expected}
        way = {  # the direction of the train each run fits best
            i: by_id[max(fit.items(), key=lambda kv: (kv[1], -order[kv[0]]))[0]].direction
            for i, fit in enumerate(fits) if fit
        }  # fmt: skip
        events: list[DescriberEvent] = []
        for direction in ("up", "down"):
            # the runs of this direction, the leading one first
            mine = []
            for i in (i for i, d in way.items() if d == direction):
                lo = min(self.circuits[tc].from_m for tc in runs[i])
                mine.append((-lo if direction == "up" else lo, i))
            for _, i in sorted(mine):
                free = [x for x in fits[i] if x in by_id and by_id[x].direction == direction]
                if not free:
                    continue
                sid = min(free, key=lambda x: (-fits[i][x], order[x]))
                s = by_id.pop(sid)
                run = self._along(runs[i], s.direction)
                self.expected.remove(s)
                self.trains[s.id] = DescribedTrain(s, run, run[-1], now, picked_up=True)
                events.append(DescriberEvent(now, s.id, "picked up", run[-1],
                              f"train {s.id} picked up at {' '.join(run)} (on the line as the "
                              "CTC started)"))  # fmt: skip
        return events

    def _runs(self, tcs: list[str]) -> list[list[str]]:
        """The occupied circuits `tcs` in runs of circuits next to each other."""
        left, out = set(tcs), []
        for tc in sorted(tcs, key=lambda x: self.circuits[x].from_m):
            if tc not in left:
                continue
            run, todo = [], [tc]
            left.discard(tc)
            while todo:
                x = todo.pop()
                run.append(x)
                for y in self.ahead(x, "up") + self.ahead(x, "down"):
                    if y in left:
                        left.discard(y)
                        todo.append(y)
            out.append(run)
        return out

    def _along(self, run: list[str], direction: Direction) -> list[str]:
        """`run` rear first in `direction` of travel."""
        up = sorted(run, key=lambda x: (self.circuits[x].from_m, self.circuits[x].to_m))
        return up if direction == "up" else up[::-1]

    def _on_booked_platform(self, s: TimetableTrain, tc: str) -> bool:
        c = self.circuits[tc]
        return any(len(c.tracks) == 1 and c.tracks[0] == stop.track and tc in
                   {t.name for t in self.line.station(stop.station).track_circuits}
                   for stop in s.stops)  # fmt: skip

    def _path(self, s: TimetableTrain) -> set[str]:
        """Every circuit `s` runs over by its timetable: onto the line, each stop's routes in and
        out and its platform, and the intervals between."""
        cached = self._paths.get(s.id)
        if cached is not None:
            return cached
        path = {s.appears_on}
        for k, stop in enumerate(s.stops):
            st = self.line.station(stop.station)
            view = self.line.view(stop.station)
            path |= {t.name for t in st.track_circuits if t.tracks == (stop.track,)}
            for name in (stop.home_route, stop.start_route):
                if name is None:
                    continue
                route = st.route(name)
                path |= set(route.track_circuits)
                iv = view.interval_of_exit(route)
                if iv is not None and (k + 1 < len(s.stops) or s.leaves_lab):
                    path |= set(iv.track_circuits)
                if name == stop.home_route and k == 0:  # the line behind its first home signal
                    path |= set(route.approach)
                    for iv in view.intervals:
                        behind = (
                            iv.east == st.number if s.direction == "up" else iv.west == st.number
                        )
                        if behind:
                            path |= set(iv.track_circuits)
        self._paths[s.id] = path
        return path

    def _at_edge(self, tc: str, direction: Direction) -> bool:
        """`tc` ends where the line does, in `direction`: a train there leaves the lab."""
        c = self.circuits[tc]
        if direction == "up":
            return c.to_m >= self.line.end_m - EPS_M
        return c.from_m <= self.line.start_m + EPS_M

    def _free_ahead(
        self, tc: str, direction: Direction, occupancy: Mapping[str, bool | None], owned: set[str]
    ) -> list[str]:
        return [x for x in self.ahead(tc, direction) if occupancy.get(x) is True and x not in owned]
