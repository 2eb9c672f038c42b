"""One station's world for the exhaustive search: the real interlocking core and trackside (a
`StationRig`), the trains on its track circuits, the faults injected, and each linked interval's
far end as an environment that says whatever the permission protocol (SPEC §6.6) allows.

Every input is a `Step` (a tuple of words, printable and replayable); `World.apply` feeds it to
the cores at the world's `now` and `World.check` tells the SPEC §6.2 invariants 1-6 and §6.7
broken in the state it reached. No clock, no I/O: time moves only when a step fires the next
deadline (`timer`).
"""

from __future__ import annotations

import io
import pickle
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.field.trackside import Trackside
from ktcs_bench.ixl import Interlocking, RouteStatus
from ktcs_bench.ixl.interlocking import ControlResult, IxlOutput
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.geometry import (
    GeometryError,
    LineGeometry,
    Track,
    beyond,
    meets,
    walk_route,
    walked_track_circuits,
)
from ktcs_bench.station.model import Direction, Interval, StationView, TrackCircuit
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.names import Function as F
from ktcs_bench.station_codes.stations import neighbour_intervals

Step = tuple[str, ...]
"""One input: its kind then its objects, e.g. ("route", "0111"), ("timer",), ("move", "0")."""


class _Rig(StationRig):
    """The rig, with every point command the interlocking gives checked as it gives it
    (invariant 2 needs the state at that instant, not after the whole input)."""

    def __init__(self, world: World, view: StationView, **kw: Any) -> None:
        self.world = world
        self.point_codes: dict[str, tuple[str, str]] = {}
        for p in view.station.points:
            self.point_codes[n.pnc(view.number, p.name)] = (p.name, "normal")
            self.point_codes[n.prc(view.number, p.name)] = (p.name, "reverse")
        super().__init__(view, **kw)

    def take(self, out: IxlOutput) -> None:
        for name, value in out.of(kinds.IO):
            hit = self.point_codes.get(name)
            if hit is not None and value == 1:
                self.world.point_commanded(hit[0], hit[1])
        super().take(out)


@dataclass
class EnvEnd:
    """The neighbour's end of one linked interval, as an environment: what it holds and says,
    and what it has read of this station's codes."""

    interval: str
    role: str  # this IXL's role for the neighbour (the link's name here)
    default_end: bool  # the neighbour departs in the interval's default direction
    link_up: bool = False
    holds: bool = False
    asking: bool = False
    drl: bool = False
    ttc: bool = False
    nobody: bool = False
    seen: dict[str, int] = field(default_factory=dict)  # our codes, as the neighbour read them


@dataclass
class Train:
    tc: str
    track: Track
    direction: Direction
    at_m: float
    origin: str  # "station", "edge" or the interval it came from


@dataclass
class Budget:
    requests: int
    points: int
    modes: int
    trains: int
    faults: int
    env: int

    def key(self) -> tuple[int, ...]:
        return (self.requests, self.points, self.modes, self.trains, self.faults, self.env)


class World:
    """See the module docstring. Built once per station (`World.start`); copied per branch."""

    def __init__(self, view: StationView, geometry: LineGeometry, budget: Budget) -> None:
        self.view = view
        self.geometry = geometry
        self.st = view.number
        self.budget = budget
        self.trains: list[Train] = []
        self.failed: set[str] = set()
        self.held_stop: set[str] = set()  # signals the operator holds at stop (accepted)
        self.links = {kinds.ATC: True, kinds.IO: True}
        self.violations: list[str] = []
        self._paths: dict[str, set[str]] = {}
        self.env: dict[str, EnvEnd] = {}
        roles = neighbour_intervals(view)
        for role, iv in roles.items():
            self.env[iv.name] = EnvEnd(
                iv.name, role, default_end=iv.default_direction == iv.toward(self.st)
            )
        self.rig = _Rig(self, view, neighbour_links=tuple(roles))
        for env in self.env.values():
            self._env_link(env, True)

    # ------------------------------------------------------------------ data

    @property
    def ixl(self) -> Interlocking:
        return self.rig.ixl

    @property
    def io(self) -> Trackside:
        return self.rig.io

    @property
    def now(self) -> float:
        return self.rig.now

    def interval(self, name: str) -> Interval:
        return self.ixl.intervals[name]

    def departures(self, iv: str) -> list[str]:
        return [
            r.name
            for r in self.view.station.routes
            if (x := self.view.interval_of_exit(r)) is not None and x.name == iv
        ]

    def interval_of_tc(self, tc: str) -> Interval | None:
        for iv in self.view.intervals:
            if tc in iv.track_circuits:
                return iv
        return None

    # ------------------------------------------------------------------ the inputs there are

    def steps(self, spawns: list[tuple[str, Track, Direction]]) -> Iterator[Step]:
        """Every input enabled in this state, within the budget left."""
        st = self.view.station
        b = self.budget
        if self.rig.next_deadline() is not None:
            yield ("timer",)
        for i, train in enumerate(self.trains):
            if self._move(train) is not None:
                yield ("move", str(i))
        if b.requests > 0:
            for r in st.routes:
                yield ("route", r.name)
        for r in st.routes:
            if self.ixl.route_status(r.name) is not RouteStatus.IDLE:
                yield ("cancel", r.name)
        if b.points > 0:
            for p, pm in self.io.points.items():
                yield ("point", p, "reverse" if pm.target == "normal" else "normal")
        if b.modes > 0:
            yield from (("mode", "take"), ("mode", "center"), ("mode", "grant"))
            for sig in self.ixl.signals:
                yield ("signal", sig, "release" if sig in self.held_stop else "stop")
        if b.trains > 0:
            for tc, track, direction in spawns:
                if self._spawn_ok(tc, direction):
                    yield ("enter", tc, track or "-", direction)
        if b.faults > 0:
            for p, pm in self.io.points.items():
                if pm.fault is None:
                    yield ("detection_lost", p)
            for t in self.ixl.tc_names:
                if t not in self.failed and not self._under_train(t):
                    yield ("tc_failed", t)
            for link, up in self.links.items():
                if up:
                    yield ("link_down", link)
        if self.failed or any(pm.fault for pm in self.io.points.values()):
            yield ("repair",)
        for link, up in self.links.items():
            if not up:
                yield ("link_up", link)
        for env in self.env.values():
            yield from self._env_steps(env)

    def _env_steps(self, env: EnvEnd) -> Iterator[Step]:
        iv = env.interval
        if not env.link_up:
            yield ("neighbour_link_up", iv)
            return
        if self.rig.to_neighbour[env.role]:
            yield ("neighbour_reads", iv)
        if self.budget.env <= 0:
            return
        yield ("neighbour_link_down", iv)
        if env.holds:
            yield ("neighbour_forgets", iv)
        phi = env.seen.get(n.phi(iv), 0)
        if not env.holds and not env.asking and phi == 1:
            yield ("neighbour_asks", iv)
        if env.asking:
            yield ("neighbour_stops_asking", iv)
        if env.holds and env.seen.get(n.prq(iv), 0) == 1 and not env.drl and not env.ttc:
            yield ("neighbour_gives", iv)
        if env.nobody and env.default_end and not env.holds and not env.ttc:
            if self._our_half_clear_seen(env):
                yield ("neighbour_takes", iv)
        if env.holds and not env.drl:
            yield ("neighbour_departure_locked", iv)
        if env.drl:
            yield ("neighbour_departure_released", iv)
        if env.holds and env.drl and not env.ttc:
            yield ("neighbour_train_departs", iv)
        if env.ttc:
            if self.budget.trains > 0 and env.holds:
                yield ("neighbour_train_arrives_here", iv)
            yield ("neighbour_half_clears", iv)

    def _our_half_clear_seen(self, env: EnvEnd) -> bool:
        return all(v == 0 for k, v in env.seen.items() if k.startswith("TTC"))

    def _spawn_ok(self, tc: str, direction: Direction) -> bool:
        if self.rig.occupancy[tc] or self._held(tc):
            return False
        iv = self.interval_of_tc(tc)
        if iv is None:
            return True
        # a train from the lab's edge arrives only with the interval worked towards us
        return self.ixl.traffic_direction(iv.name) == iv.toward(self.st)

    def _held(self, tc: str) -> bool:
        return any(tc in rs.held_tcs for rs in self.ixl.routes.values())

    def _under_train(self, tc: str) -> bool:
        return any(t.tc == tc for t in self.trains)

    # ------------------------------------------------------------------ applying an input

    def apply(self, step: Step) -> ControlResult | None:
        """Feed one input; the interlocking's answer when it was a control answered at once."""
        kind, args = step[0], step[1:]
        rig, st, now = self.rig, self.st, self.now
        b = self.budget
        answer: ControlResult | None = None
        if kind == "timer":
            due = rig.next_deadline()
            assert due is not None
            rig.handle_timer(max(due, now))
        elif kind == "route":
            b.requests -= 1
            answer = rig.request(n.rsc(st, args[0]))
        elif kind == "cancel":
            answer = rig.request(n.rcc(st, args[0]))
        elif kind == "point":
            b.points -= 1
            code = n.src(st, args[0]) if args[1] == "reverse" else n.snc(st, args[0])
            answer = rig.request(code)
        elif kind == "signal":
            b.modes -= 1
            answer = rig.request(n.ssc(st, args[0]), int(args[1] == "stop"))
            if answer is not None and answer.accepted:
                (self.held_stop.add if args[1] == "stop" else self.held_stop.discard)(args[0])
        elif kind == "mode":
            b.modes -= 1
            if args[0] == "center":
                answer = rig.request(n.cmq(st))
            else:
                rig.take(self.ixl.local(args[0], now))
        elif kind == "enter":  # a train comes onto the station's rails
            b.trains -= 1
            tc, track, direction = args[0], None if args[1] == "-" else args[1], args[2]
            self._add_train(tc, track, direction, "station")  # type: ignore[arg-type]
        elif kind == "move":
            self._step_train(int(args[0]))
        elif kind == "detection_lost":
            b.faults -= 1
            rig.from_field(self.io.fail_point(args[0], "detection", now).changes)
        elif kind == "tc_failed":
            b.faults -= 1
            self.failed.add(args[0])
            self._report(args[0])
        elif kind == "repair":
            failed, self.failed = self.failed, set()
            rig.from_field(self.io.clear_faults(now).changes)
            for tc in sorted(failed):
                self._report(tc)
        elif kind in ("link_down", "link_up"):
            up = kind == "link_up"
            if not up:
                b.faults -= 1
            self.links[args[0]] = up
            rig.set_link(args[0], up)
        else:
            self._apply_env(kind, self.env[args[0]])
        if b.env <= 0:
            # a neighbour that may no longer act reads what it is told at once: its reading
            # changes nothing for this IXL (only an asker takes anything from it)
            for env in self.env.values():
                if env.link_up and not env.asking and self.rig.to_neighbour[env.role]:
                    self._env_read(env)
        return answer

    def _apply_env(self, kind: str, env: EnvEnd) -> None:
        iv = env.interval
        if kind == "neighbour_link_up":
            self._env_link(env, True)
            return
        if kind == "neighbour_reads":
            self._env_read(env)
            return
        self.budget.env -= 1
        if kind == "neighbour_link_down":
            self._env_link(env, False)
            return
        send: dict[str, int] = {}
        if kind == "neighbour_asks":
            env.asking = True
            send[n.prq(iv)] = 1
        elif kind == "neighbour_stops_asking":
            env.asking = False
            send[n.prq(iv)] = 0
        elif kind == "neighbour_gives":
            env.holds = False
            send[n.phi(iv)] = 0
        elif kind == "neighbour_takes":
            env.holds, env.nobody = True, False
            send[n.phi(iv)] = 1
        elif kind == "neighbour_forgets":
            env.holds = env.drl = env.asking = False
            send.update({n.phi(iv): 0, n.drl(iv): 0, n.prq(iv): 0})
        elif kind == "neighbour_departure_locked":
            env.drl = True
            send[n.drl(iv)] = 1
        elif kind == "neighbour_departure_released":
            env.drl = False
            send[n.drl(iv)] = 0
        elif kind == "neighbour_train_departs":
            env.ttc = True
            send[self._env_ttc_name(env)] = 1
        elif kind == "neighbour_train_arrives_here":
            # its train runs out of its half into ours, towards us
            self.budget.trains -= 1
            env.ttc = False
            send[self._env_ttc_name(env)] = 0
            interval = self.interval(iv)
            half = self.view.owned_half(interval)
            far = half[-1] if interval.toward(self.st) == "down" else half[0]
            self._add_train(far, None, interval.toward(self.st), iv)
        elif kind == "neighbour_half_clears":
            env.ttc = False
            send[self._env_ttc_name(env)] = 0
        else:
            raise ValueError(f"unknown step {kind!r}")
        self.rig.deliver(env.role, send)

    def _env_ttc_name(self, env: EnvEnd) -> str:
        return next(c for c in self.ixl.input_names(env.role) if c.startswith(F.TTC.value))

    def _env_codes(self, env: EnvEnd) -> dict[str, int]:
        iv = env.interval
        codes = {
            n.phi(iv): int(env.holds), n.prq(iv): int(env.asking), n.drl(iv): int(env.drl),
        }  # fmt: skip
        for name in self.ixl.input_names(env.role):
            if name.startswith(F.TTC.value):
                codes[name] = int(env.ttc)
        return codes

    def _env_link(self, env: EnvEnd, up: bool) -> None:
        """The IXL-IXL link down, or up with both full states crossing (the resync)."""
        env.link_up = up
        self.rig.set_link(env.role, up)
        self.rig.to_neighbour[env.role].clear()
        if not up:
            env.asking = False
            env.seen = {}
            return
        env.seen = dict(self.ixl.full_state(env.role))
        if not env.holds:
            env.nobody = env.seen.get(n.phi(env.interval), 0) == 0
            if env.nobody and env.default_end and not env.ttc and self._our_half_clear_seen(env):
                env.holds, env.nobody = True, False  # the default end takes it at start-up
        self.rig.deliver(env.role, self._env_codes(env))

    def _env_read(self, env: EnvEnd) -> None:
        """The neighbour reads what this IXL said; an asker that reads the PHI go 1 -> 0
        becomes the holder (the protocol's only way to take a given permission)."""
        iv = env.interval
        before = env.seen.get(n.phi(iv), 0)
        changes, self.rig.to_neighbour[env.role] = self.rig.to_neighbour[env.role], []
        for name, value in changes:
            env.seen[name] = value
        if env.asking and before == 1 and env.seen.get(n.phi(iv), 0) == 0:
            env.asking, env.holds = False, True
            self.rig.deliver(env.role, {n.phi(iv): 1, n.prq(iv): 0})
        elif not env.holds and env.seen.get(n.phi(iv), 0) == 1:
            env.nobody = False

    # ------------------------------------------------------------------ trains

    def _add_train(self, tc: str, track: Track, direction: Direction, origin: str) -> None:
        circuit = self._tc(tc)
        train = Train(tc, track, direction, (circuit.from_m + circuit.to_m) / 2, origin)
        self.trains.append(train)
        iv = self.interval_of_tc(tc)
        if iv is not None:
            self._entering_interval(iv, direction, tc)
        self._report(tc)

    def _tc(self, name: str) -> TrackCircuit:
        return next(t for t in self.view.track_circuits if t.name == name)

    def _move(self, train: Train) -> tuple[str | None, Track, float, list[str]] | None:
        """Where the train's head runs next: (track circuit or None: off this station's rails,
        track, chainage, what it did to points); None when a signal at stop holds it."""
        circuit = self._tc(train.tc)
        up = train.direction == "up"
        edge = circuit.to_m if up else circuit.from_m
        to = edge + (0.5 if up else -0.5)
        for sig in self.view.station.lamp_signals:
            ahead = train.at_m < sig.position_m <= to if up else to <= sig.position_m < train.at_m
            if not ahead or sig.direction != train.direction:
                continue
            if sig.track is not None and train.track is not None and sig.track != train.track:
                continue
            if sig.track is not None and train.track is None:
                continue
            if self.ixl.aspect(sig.name) == "R":
                return None
        track = train.track
        done: list[str] = []
        blades = self.io.blades()
        for number, p in self.geometry.passed(train.at_m, to):
            if number != self.st:
                continue
            meeting = meets(p, track, up)
            if meeting is None:
                continue
            lie = blades[p.name]
            if lie not in ("normal", "reverse"):
                done.append(f"derailed {self.st} {p.name}")
                return (None, track, to, done)
            if meeting != "toe" and meeting != lie:
                done.append(f"trailed point {self.st} {p.name}")
            track = beyond(p, meeting, meeting if meeting != "toe" else lie)  # type: ignore[arg-type]
        for tc in self.view.track_circuits:
            if tc.covers(to) and self.geometry.carries(tc, track):
                return (tc.name, track, to, done)
        return (None, track, to, done)

    def _step_train(self, i: int) -> None:
        train = self.trains[i]
        move = self._move(train)
        assert move is not None
        new, track, to, done = move
        for what in done:
            self.violations.append(f"SPEC §6.7: {what} (train from {train.origin})")
        old = train.tc
        if new is None:
            self.trains.pop(i)
            iv = self.interval_of_tc(old)
            if iv is not None and iv.name in self.env and iv.toward(self.st) != train.direction:
                env = self.env[iv.name]
                env.ttc = True  # our train runs on into the neighbour's half
                if env.link_up:
                    self.rig.deliver(env.role, {self._env_ttc_name(env): 1})
        else:
            train.tc, train.track, train.at_m = new, track, to
            iv = self.interval_of_tc(new)
            if iv is not None and self.interval_of_tc(old) is None:
                self._entering_interval(iv, train.direction, new)
            self._report(new)
        self._report(old)

    def _entering_interval(self, iv: Interval, direction: Direction, tc: str) -> None:
        """Invariant 6: no train enters an interval against a train in it or against the
        direction of a locked departure route."""
        away = direction != iv.toward(self.st)
        env = self.env.get(iv.name)
        if away and env is not None and (env.drl or env.ttc):
            self.violations.append(
                f"SPEC §6.2 (6): a train runs into interval {iv.name} at {tc} towards the "
                f"neighbour while its departure route is locked or its train is in the interval"
            )
        if not away:
            locked = [r for r in self.departures(iv.name)
                      if self.ixl.route_status(r) is not RouteStatus.IDLE]  # fmt: skip
            if locked:
                self.violations.append(
                    f"SPEC §6.2 (6): a train runs into interval {iv.name} at {tc} against "
                    f"departure route {locked[0]}, locked"
                )

    def _report(self, tc: str) -> None:
        """The ATC's report of one track circuit (its interval's IZC with it)."""
        value = tc in self.failed or self._under_train(tc)
        rig = self.rig
        if rig.occupancy[tc] == value:
            return
        # as `StationRig.occupy`, but only the codes that change (the whole picture each time
        # cost the search most of its time)
        rig.occupancy[tc] = value
        rig.io.set_occupancy({tc: value}, rig.now)
        codes = {tc: int(value)}
        iv = self.interval_of_tc(tc)
        if iv is not None:
            half = self.view.owned_half(iv)
            codes[n.izc(iv.name)] = int(any(rig.occupancy[t] for t in half))
        rig.take(self.ixl.receive(kinds.ATC, codes, rig.now))

    def occupied(self, tc: str) -> bool:
        """Occupied in truth, or reported so (a failed track circuit)."""
        return tc in self.failed or self._under_train(tc)

    # ------------------------------------------------------------------ invariants

    def point_commanded(self, point: str, position: str) -> None:
        """Invariant 2, at the instant the command is given."""
        pm = self.io.points.get(point)
        if pm is None or pm.target == position:
            return  # no move
        p = self.view.station.point(point)
        for tc in p.track_circuits:
            if self._under_train(tc):
                self.violations.append(
                    f"SPEC §6.2 (2): point {point} commanded {position} under a train in {tc}"
                )
        for rs in self.ixl.routes.values():
            if point in rs.held_points:
                want = {s.point: s.position for s in rs.route.all_points}[point]
                if not (rs.status is RouteStatus.SETTING and want == position):
                    self.violations.append(
                        f"SPEC §6.2 (2): point {point} commanded {position} while locked by "
                        f"route {rs.route.name} ({rs.status.value})"
                    )

    def forget_logs(self) -> None:
        """Drop what the cores logged: not state, and copied with every branch otherwise."""
        self.rig.events.clear()
        self.rig.results.clear()
        self.ixl.log.clear()
        self.io.log.clear()

    def check(self) -> list[str]:
        """The invariants broken in this state (after the input that reached it)."""
        out = list(self.violations)
        self.violations.clear()
        out += self._no_element_locked_twice()
        out += self._proceed_only_when_safe()
        out += self._one_departure_per_interval()
        return out

    def _no_element_locked_twice(self) -> list[str]:
        out = []
        seen: dict[str, str] = {}
        for rs in self.ixl.routes.values():
            r = rs.route
            extra = (rs.held_tcs - set(r.all_track_circuits)) | (
                rs.held_points - {s.point for s in r.all_points}
            )
            if extra:
                out.append(f"SPEC §6.2 (1): route {r.name} holds {sorted(extra)}, not its own")
            for element in sorted(rs.held_tcs | rs.held_points):
                if element in seen:
                    out.append(
                        f"SPEC §6.2 (1): {element} held by routes {seen[element]} and {r.name}"
                    )
                seen[element] = r.name
        whole = {name for name, rs in self.ixl.routes.items() if rs.whole}
        for name in sorted(whole):
            clash = whole & set(self.ixl.routes[name].route.conflicts)
            if clash and name < min(clash):
                out.append(
                    f"SPEC §6.2 (1): conflicting routes {name} and {min(clash)} locked together"
                )
        return out

    def path_tcs(self, route: str) -> set[str]:
        """The track circuits of the route's path and overlap as the geometry runs them (not
        as its data lists them: a track circuit dropped from the data is still checked)."""
        found = self._paths.get(route)
        if found is None:
            r = self.view.station.route(route)
            found = set(r.all_track_circuits)
            try:
                walk = walk_route(self.view.station, r, f"route {route}")
            except GeometryError:
                pass
            else:
                found |= walked_track_circuits(self.geometry, walk.route + walk.overlap)
            found &= set(self.ixl.tc_names)
            self._paths[route] = found
        return found

    def _proceed_only_when_safe(self) -> list[str]:
        out = []
        for sig in self.view.station.lamp_signals:
            aspect = self.ixl.aspect(sig.name)
            if aspect == "R":
                continue
            why = self._unsafe_proceed(sig.name)
            if why:
                out.append(f"SPEC §6.2 (3, 4): signal {sig.name} shows {aspect} with {why}")
        return out

    def _unsafe_proceed(self, signal: str) -> str | None:
        if not (self.links[kinds.ATC] and self.links[kinds.IO]):
            return "a link down"
        if signal in self.held_stop:
            return "the operator holding it at stop"
        set_routes = [rs for rs in self.ixl.routes.values()
                      if rs.route.entry == signal and rs.status is RouteStatus.SET]  # fmt: skip
        if len(set_routes) != 1:
            return "no set route"
        rs = set_routes[0]
        r = rs.route
        if not set(r.track_circuits) <= rs.held_tcs:
            return f"route {r.name}'s track circuits not locked"
        if not {s.point for s in r.points} <= rs.held_points:
            return f"route {r.name}'s points not locked"
        for element in sorted(rs.overlap_elements - rs.held_tcs - rs.held_points):
            holders = [o for o in self.ixl.routes.values()
                       if element in o.held_tcs | o.held_points and o.route.entry == r.exit]  # fmt: skip
            if not holders:
                return f"route {r.name}'s overlap element {element} not locked"
        for s in r.all_points:
            pm = self.io.points[s.point]
            bits = pm.bits()
            detected = "normal" if bits["SNI"] else "reverse" if bits["SRI"] else None
            if pm.blades() != s.position or detected != s.position:
                return f"point {s.point} {pm.blades()} (detected {detected}), route {r.name} needs {s.position}"
        for tc in sorted(self.path_tcs(r.name)):
            if self.occupied(tc):
                return f"{tc} occupied (route {r.name})"
        iv = self.view.interval_of_exit(r)
        if iv is not None and iv.name in self.env:
            env = self.env[iv.name]
            if env.holds or env.drl:
                return f"the neighbour holding interval {iv.name}'s permission (route {r.name})"
        return None

    def _one_departure_per_interval(self) -> list[str]:
        """Invariant 5, and at most one holder of each interval's permission."""
        out = []
        for name, env in self.env.items():
            ours = [r for r in self.departures(name)
                    if self.ixl.route_status(r) is not RouteStatus.IDLE]  # fmt: skip
            if ours and env.drl:
                out.append(f"SPEC §6.2 (5): departure route {ours[0]} into {name} locked while "
                           "the neighbour's departure route into it is locked")  # fmt: skip
            if self.ixl.ends[name].holds and env.holds:
                out.append(f"SPEC §6.6: both ends hold interval {name}'s permission")
        return out

    # ------------------------------------------------------------------ copying and hashing

    def key(self, static: frozenset[int]) -> tuple[Any, ...]:
        """The state, canonically: equal for states that behave alike from here on (times are
        taken relative to `now`; logs and what is derived from the state left out)."""
        now = self.now
        return (
            _canon(self.rig, now, static),
            tuple((t.tc, t.track, t.direction, t.at_m) for t in self.trains),
            tuple(sorted(self.failed)),
            tuple(sorted(self.held_stop)),
            tuple(sorted(self.links.items())),
            tuple(
                (
                    e.link_up,
                    e.holds,
                    e.asking,
                    e.drl,
                    e.ttc,
                    e.nobody,
                    tuple(sorted(e.seen.items())),
                )
                for e in self.env.values()
            ),
            self.budget.key(),
        )


# names of attributes that are logs, links to the world, or derived from the rest of the state
_SKIP = frozenset({
    "log", "_events", "_results", "events", "results", "_log_limit", "world", "point_codes",
    "view", "codes", "_names", "_controls", "_inputs", "_command_names", "_sent", kinds.CTC, kinds.ATC,  # the rig's pictures of what it told them
    "on_ctc", "_points_in", "_departures", "intervals", "outputs", "tc_names", "neighbours",
    "tc_sources", "startup_release_s", "_expected", "peer_has_ttc", "now", "_paths",
    # the trackside's relays and the rig's occupancy follow the trains and failures (in the key);
    # the trackside's demands and lamp commands are the interlocking's outputs
    "occupancy", "relays", "_demand", "_sgc",
})  # fmt: skip
PAST_S = 1000.0
"""A time further back than every timer of the station data is only "past"."""


_EXACT = frozenset({bool, int, str, type(None)})


def _canon(obj: Any, now: float, static: frozenset[int]) -> Any:
    """A hashable, order-free picture of `obj` made of plain values (marshal takes it): times
    relative to `now`, enums by value, station data by id."""
    t = type(obj)
    if t in _EXACT:
        return obj
    if t is float:
        rel = round(obj - now, 6) + 0.0  # no -0.0: equal times hash alike
        return "past" if rel < -PAST_S else rel
    if isinstance(obj, Enum):
        return obj.value
    if t is dict:
        items = [
            (k if type(k) is str else _canon(k, now, static),
             v if type(v) in _EXACT else _canon(v, now, static))
            for k, v in obj.items()
        ]  # fmt: skip
        return tuple(sorted(items, key=_first))
    if t is set or t is frozenset:
        values = [v if type(v) in _EXACT else _canon(v, now, static) for v in obj]
        try:
            return tuple(sorted(values))
        except TypeError:
            return tuple(sorted(values, key=repr))
    if t is list or t is tuple:
        return tuple([v if type(v) in _EXACT else _canon(v, now, static) for v in obj])
    if id(obj) in static:
        return id(obj)
    names = getattr(obj, "__dict__", None)
    if names is None:
        names = {s: getattr(obj, s) for s in _slots(t)}
    return tuple([_canon(v, now, static) for k, v in names.items() if k not in _SKIP])


def _first(item: tuple[Any, Any]) -> str:
    return repr(item[0]) if not isinstance(item[0], str) else item[0]


def _slots(cls: type) -> tuple[str, ...]:
    out: list[str] = []
    for c in cls.__mro__:
        out += list(getattr(c, "__slots__", ()))
    return tuple(out)


_STATIC: dict[int, Any] = {}
"""Station data the copies share, by id (they are frozen): pickled as a reference."""


def _static(key: int) -> Any:
    return _STATIC[key]


def _by_reference(obj: Any) -> tuple[Any, tuple[int]]:
    return _static, (id(obj),)


class Copier:
    """Copies worlds by pickling them, the station data (frozen, shared) left out of the copy."""

    def __init__(self, template: World) -> None:
        view = template.view
        objects: list[Any] = [view, view.line, view.station, template.geometry]
        objects += list(view.line.stations.values())
        for st in view.line.stations.values():
            objects += [*st.routes, *st.points, *st.signals, *st.track_circuits]
        objects += [*view.line.track_circuits, *view.line.intervals]
        objects += [template.ixl.codes, template.io.codes]
        for o in objects:
            _STATIC[id(o)] = o
        self.static_ids = frozenset(id(o) for o in objects)
        self.table = {type(o): _by_reference for o in objects}

    def dump(self, world: World) -> bytes:
        buf = io.BytesIO()
        pickler = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
        pickler.dispatch_table = self.table
        pickler.dump(world)
        return buf.getvalue()

    def load(self, data: bytes) -> World:
        world: World = pickle.loads(data)
        return world

    def copy(self, world: World) -> World:
        return self.load(self.dump(world))


def spawn_places(view: StationView) -> list[tuple[str, Track, Direction]]:
    """Where a train may appear: standing on a station track (one track, no point), facing
    either way, and at the lab's edge running in (a boundary interval's far track circuit)."""
    out: list[tuple[str, Track, Direction]] = []
    points = {tc for p in view.station.points for tc in p.track_circuits}
    for tc in view.station.track_circuits:
        if len(tc.tracks) == 1 and tc.name not in points:
            for d in ("up", "down"):
                out.append((tc.name, tc.tracks[0], d))
    for iv in view.intervals:
        if iv.boundary:
            half = view.owned_half(iv)
            if half:
                toward = iv.toward(view.number)
                out.append((half[0] if toward == "up" else half[-1], None, toward))
    return out
