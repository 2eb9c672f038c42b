"""The station interlocking (SPEC §6.2), sans-I/O: inputs by code name, outputs by code name.

Inputs: CTC controls (`control`, by code name), local-panel actions (`local`), Type I
code changes from the ATC and the trackside (`receive`), link up/down (`link_state`) and timers
(`handle_timer` at `next_deadline()`: the automatic center-mode grant, timed route and overlap
releases, the 3 s an ask for an interval's permission waits -- the timer shape of every core,
`ktcs_bench.timed`). Every call takes `now` (seconds) and returns an `IxlOutput`: per peer role
(`kinds.PEER_ROLES`: the CTC, the ATC, the trackside's `io`; and each neighbouring IXL it is
linked with, `kinds.WEST`/`kinds.EAST`) the changes of its IXL->ROLE chart, control results and
events.

Traffic direction (SPEC §6.6, `ixl.direction`): each adjacent interval's permission is one
`IntervalEnd`; only its holder locks a departure route into the interval. A departure asked at
the end that does not hold it asks the neighbour (PRQ) and stays pending: it is answered -- in a
later output's `results` -- when the permission comes (the route is then set with every check as
of that moment) or refused with reason `direction` after 3 s without it; it is refused at once
when the permission cannot be asked (link down, nothing known). `neighbour_links` names the
neighbour roles this IXL has a link on; an interval whose neighbour it is not linked with (a
single station on the bench) is worked as if its default end held the permission for good: the
default end departs, the other end refuses departures into it (`direction`). The neighbour links
are not among the links a signal depends on: a holder departs with its neighbour link down. After every input the whole station is
re-evaluated at once, so a failing condition puts a signal to stop in the same call that reported
it (invariant 4: within one cycle).

Fail-safe defaults: links start down; a track circuit is occupied until its source reports it
clear and whenever a link that reports it is down; a point has no detection until the trackside
reports it and whenever the trackside link is down. A link that went down is believed again only
for what it reports after it came back: nothing it said before the outage is reused.

Start-up locking (`startup_locking=True`: an interlocking restarted in a running railway, after a
crash): it knows nothing of the routes its predecessor had set, while a train may still be running
on one of them, braking on the most restrictive code. So it starts with every track circuit and
point of its station locked (no route over them, no point moved): when its first live occupancy
shows the station and its plain line clear, the lock goes at once; otherwise it goes after the
longest approach-locking time of the station's routes, as a cancelled route's would -- time for
any train to have stopped. Nor does it demand any point position of its own accord: each point's
machine stays where its blades lie (PNC and PRC both off) until a route or an individual control
demands it, each with its own checks (not locked, its track circuits clear). A restarted
interlocking that demanded its default would throw every reverse point back to normal; one that
demanded the position it reads would throw the blades over whenever detection is wrong (the
wrong-side `crossed` fault: blades lying normal reported reverse) -- either under a train standing
on the point or a route its predecessor had locked. A cold start with the railway at rest (a
lab's start: the trains stand where the lab puts them) has neither.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from ktcs_bench import kinds
from ktcs_bench.ixl.direction import Facts, Holding, IntervalEnd
from ktcs_bench.ixl.modes import Mode, ModeControl
from ktcs_bench.ixl.points import BITS, Detection, PointState
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.ixl.routes import RouteState, RouteStatus
from ktcs_bench.ixl.signals import SignalState, downgrade, fit
from ktcs_bench.station.loader import onward
from ktcs_bench.station.model import Direction, Interval, PointPosition, Route, StationView
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.names import Function as F
from ktcs_bench.station_codes.stations import StationCodes, neighbour_intervals

LINKS = kinds.TYPE1_ROLES
"""The Type I links, by peer role: the ATC's and the trackside's."""
OUTPUTS = kinds.PEER_ROLES
"""Every peer role the IXL sends to, each on its own IXL->ROLE chart."""


@dataclass(frozen=True, slots=True)
class IxlEvent:
    time: float
    kind: str  # control, mode, route, point, signal, train, link, fault
    text: str


@dataclass(frozen=True, slots=True)
class ControlResult:
    name: str | None  # None when the CTC->IXL chart has no such control
    accepted: bool
    reason: Reason
    late: bool = False
    """The answer to an earlier CTC control that waited for an interval's permission."""


@dataclass
class IxlOutput:
    changes: dict[str, list[tuple[str, int]]] = field(default_factory=dict)
    """Per peer role (`OUTPUTS`), the code changes of its IXL->ROLE chart (none: no entry)."""
    results: list[ControlResult] = field(default_factory=list)
    events: list[IxlEvent] = field(default_factory=list)

    def of(self, role: str) -> list[tuple[str, int]]:
        """The code changes for peer `role` (none: empty)."""
        return self.changes.get(role, [])


class Interlocking:
    """One station's IXL. `tc_sources` names the links whose reports give track occupancy;
    `neighbour_links` the neighbouring IXLs it is linked with (see the module docstring)."""

    direction_check_disabled_for_tests = False
    """Test-only, never set by the bench: when True a departure route into an interval is locked
    and cleared whether or not this IXL holds the interval's permission -- the IXL before SPEC
    §6.6, so that a test shows the whole-system search finding a head-on
    (tests/lab/test_system_safety.py). The permission itself is still worked and coded."""

    occupancy_check_disabled_for_tests = False
    """Test-only, never set by the bench: when True a signal clears over occupied track circuits
    -- a check switched off, that `ixl verify`'s search must catch (tests/verify)."""

    def __init__(
        self,
        view: StationView,
        *,
        mode: Mode = Mode.LOCAL,
        auto_grant_s: float | None = None,
        tc_sources: Iterable[str] = (kinds.ATC,),
        log_limit: int = 10_000,
        startup_locking: bool = False,
        neighbour_links: Iterable[str] = (),
    ) -> None:
        self.view = view
        self.st = view.number
        st = view.station
        self.modes = ModeControl(mode, auto_grant_s)
        self.tc_sources = tuple(tc_sources)
        for src in self.tc_sources:
            if src not in LINKS:
                raise ValueError(f"unknown track-circuit source {src!r}")
        self.tc_names = tuple(t.name for t in view.track_circuits)
        self.points = {p.name: PointState(p) for p in st.points}
        self.signals = {s.name: SignalState(s) for s in st.lamp_signals}
        self.routes = {r.name: RouteState(r) for r in st.routes}
        self.intervals: dict[str, Interval] = {iv.name: iv for iv in view.intervals}
        self.codes = StationCodes(view)
        linked = set(neighbour_links)
        for role in linked - set(kinds.NEIGHBOUR_ROLES):
            raise ValueError(f"unknown neighbour link {role!r}")
        self.neighbours: dict[str, str] = {
            role: iv.name for role, iv in neighbour_intervals(view).items() if role in linked
        }
        """Role -> interval of each neighbouring IXL this one is linked with (non-boundary)."""
        for missing in sorted(linked - set(self.neighbours)):
            raise ValueError(f"station {self.st} has no {missing} neighbour")
        self.ends: dict[str, IntervalEnd] = {}
        roles = {name: role for role, name in self.neighbours.items()}
        for iv in view.intervals:
            peer = roles.get(iv.name)
            has_ttc = peer is not None and any(
                c.function is F.TTC for c in self.codes.specs[kinds.chart_name(peer, False)].names
            )
            self.ends[iv.name] = IntervalEnd(iv, self.st, linked=peer is not None,
                                             peer_has_ttc=has_ttc)  # fmt: skip
        self._departures: dict[str, tuple[str, ...]] = {
            iv: tuple(r.name for r in st.routes if (x := view.interval_of_exit(r)) and x.name == iv)
            for iv in self.intervals
        }
        self._waiting: dict[str, list[tuple[str, str, str]]] = {iv: [] for iv in self.intervals}
        # a train of ours in the interval (entered by our departure), and seen in its far half
        self._transit = dict.fromkeys(self.intervals, False)
        self._far_seen = dict.fromkeys(self.intervals, False)
        self.link_up = dict.fromkeys((*LINKS, *self.neighbours), False)
        self.tc_reports: dict[str, dict[str, int]] = {src: {} for src in LINKS}
        self.izc: dict[str, int] = {}
        self.ttc: dict[str, int] = {}
        self._points_in = {p.name: p.track_circuits for p in st.points}
        self._proceed_before: dict[str, bool] = dict.fromkeys(self.signals, False)
        # occupancy as the last evaluation with live reports saw it (a train's sequence is read
        # by comparing each live picture with this one)
        self._occupied_before: dict[str, bool] = dict.fromkeys(self.tc_names, True)
        self._noticed: set[str] = set()
        self._controls = set(self.codes.names("ctc_to_ixl"))
        self._inputs = {link: set(self.input_names(link)) for link in self.link_up}
        self.outputs: tuple[str, ...] = (*OUTPUTS, *self.neighbours)
        """Every role this IXL sends to: its peers' and its linked neighbours'."""
        self.log: list[IxlEvent] = []
        self._log_limit = log_limit
        self._events: list[IxlEvent] = []
        self._results: list[ControlResult] = []
        # start-up locking (see the module docstring): released at the first live occupancy if
        # everything is clear, else on its timer, started then
        self.startup_held: set[str] = (
            set(self.tc_names) | set(self.points) if startup_locking else set()
        )
        self.startup_release_s = max((r.approach_release_s for r in st.routes), default=0.0)
        self.startup_release_at: float | None = None
        if startup_locking:
            for ps in self.points.values():
                ps.demanded = None
        self._names = _OutputNames(self)
        self._evaluate(0.0)
        self._sent = {k: self.full_state(k) for k in self.outputs}
        self._events.clear()

    # ------------------------------------------------------------------ public inputs

    def control(self, name: str, value: int, now: float) -> IxlOutput:
        """A CTC control (Type II CONTROL item): the code's name and its value. Its result is in
        the output's `results`, except a departure waiting for the interval's permission: its
        result comes in the output of the input that answers it (`pending`)."""
        self._answer(self._control(name, value, now, source=kinds.CTC))
        return self._finish(now)

    def local_control(self, name: str, value: int, now: float) -> IxlOutput:
        """The same controls from the local panel: accepted only in local mode."""
        self._answer(self._control(name, value, now, source="local"))
        return self._finish(now)

    def pending(self) -> list[tuple[str, str]]:
        """The route requests waiting for an interval's permission: (control name, source)."""
        return [(name, src) for waits in self._waiting.values() for _, name, src in waits]

    def _answer(self, result: ControlResult | None) -> None:
        if result is not None:
            self._results.append(result)

    def local(self, action: str, now: float) -> IxlOutput:
        """Local operator: "grant" / "refuse" a center-mode request, or "take" local control."""
        if action == "grant":
            if self.modes.grant():
                self._event(now, "mode", "local operator granted center mode")
        elif action == "refuse":
            if self.modes.refuse():
                self._event(now, "mode", "local operator refused center mode")
        elif action == "take":
            if self.modes.to_local():
                self._event(now, "mode", "local operator took local control")
        else:
            raise ValueError(f"unknown local action {action!r} (grant, refuse, take)")
        return self._finish(now)

    def receive(self, link: str, codes: Mapping[str, int], now: float) -> IxlOutput:
        """Code changes or a full state from a Type I peer: one of `LINKS`, or a linked
        neighbour (`neighbours`).

        Codes that come while the link is in communication error are ignored: the IXL has gone
        fail-safe for that link and rebuilds its view from what comes after `link_state(up)`.
        """
        if not self.link_up[link]:
            self._event(now, "fault", f"{link}: codes on a link in communication error ignored")
            return self._finish(now)
        known = self._inputs[link]
        for name, state in codes.items():
            if name not in known:
                self._event(now, "fault", f"{link}: unknown code {name!r} ignored")
                continue
            self._apply_input(link, name, int(state), now)
        return self._finish(now)

    def link_state(self, link: str, up: bool, now: float) -> IxlOutput:
        """A Type I link came up or went into communication error."""
        if link not in self.link_up:
            raise ValueError(f"unknown link {link!r}")
        if self.link_up[link] != up:
            self.link_up[link] = up
            what = "up" if up else "in communication error"
            self._event(now, "link", f"{link} link {what}")
            if link in self.neighbours:
                self.ends[self.neighbours[link]].link_state(up, now)
            elif not up:
                # What the link reported is stale from now on: after recovery each report is
                # believed again only once the peer sends it (its ALL_INFO), not before.
                self.tc_reports[link].clear()
                if link == kinds.ATC:
                    self.izc.clear()
                else:
                    for ps in self.points.values():
                        ps.bits.clear()
                    for sig in self.signals.values():
                        sig.lamp_bits.clear()
                        sig.lamp_reported = False
        return self._finish(now)

    def handle_timer(self, now: float) -> IxlOutput:
        """Timers: call at (or after) `next_deadline()`."""
        return self._finish(now)

    # ------------------------------------------------------------------ public queries

    def next_deadline(self) -> float | None:
        """The next automatic grant, timed route release or overlap release. An overlap timer
        waits while no train movement can be read (a dead occupancy link): it is no deadline
        then, and the report that brings the link back runs it."""
        due = [self.modes.next_deadline()]
        due += [end.next_deadline() for end in self.ends.values()]
        live = self._reports_live()
        # like an overlap timer, the start-up lock's waits while occupancy cannot be read
        due.append(self.startup_release_at if self.startup_held and live else None)
        for rs in self.routes.values():
            due += [rs.release_at, rs.overlap_at if live else None]
        return min((d for d in due if d is not None), default=None)

    def control_names(self) -> tuple[str, ...]:
        return self.codes.names("ctc_to_ixl")

    def input_names(self, link: str) -> tuple[str, ...]:
        return self.codes.names(kinds.chart_name(link, outward=False))

    def occupied(self, tc: str) -> bool:
        """Occupancy as the interlocking takes it (fail-safe: unknown or link down = occupied)."""
        for src in self.tc_sources:
            if not self.link_up[src] or self.tc_reports[src].get(tc, 1) != 0:
                return True
        return False

    def detection(self, point: str) -> Detection:
        """Where the point is, as far as it proves anything: lost while the trackside link is
        down, moving to its call until the trackside has answered that call."""
        if not self.link_up[kinds.IO]:
            return "none"
        ps = self.points[point]
        reported = ps.reported
        if not ps.answered and reported != "none":
            return "to_normal" if ps.demanded == "normal" else "to_reverse"
        return reported

    def route_status(self, route: str) -> RouteStatus:
        return self.routes[route].status

    def aspect(self, signal: str) -> str:
        """The commanded aspect."""
        return self.signals[signal].commanded

    def full_state(self, kind: str) -> dict[str, int]:
        """Every code of the IXL->ROLE chart of peer role `kind` (one of `outputs`)."""
        states = {kinds.CTC: self._ctc_state, kinds.ATC: self._atc_state, kinds.IO: self._io_state}
        if kind in self.neighbours:
            return self._neighbour_state(self.neighbours[kind])
        if kind not in states:
            raise ValueError(f"unknown output {kind!r} ({', '.join(self.outputs)})")
        return states[kind]()

    def traffic_direction(self, interval: str) -> Direction | None:
        """The direction interval `interval` is worked in as this IXL knows it (None: nobody
        holds its permission, as far as it knows)."""
        return self.ends[interval].direction

    def holding(self, interval: str) -> Holding:
        """This IXL's part in the interval's permission."""
        return self.ends[interval].holding

    # ------------------------------------------------------------------ controls

    def _control(self, name: str, value: int, now: float, source: str) -> ControlResult | None:
        code = self.codes.parse_code(name) if name in self._controls else None
        if code is None:
            self._event(now, "control", f"{source}: unknown control code {name!r} rejected")
            return ControlResult(None, False, Reason.UNKNOWN_CODE)
        reason = self._dispatch(code.function, code.object, value, now, source)
        if reason is None:
            self._wait(code.object, name, source, now)
            return None
        verdict = "accepted" if reason is Reason.NONE else f"rejected: {reason.text}"
        self._event(now, "control", f"{source}: {name}={value} {verdict}")
        return ControlResult(name, reason is Reason.NONE, reason)

    def _dispatch(self, kind: F, obj: str, value: int, now: float, source: str) -> Reason | None:
        """The control's answer; None: a departure waits for its interval's permission."""
        if kind is F.CMQ:
            if value and self.modes.request_center(now):
                self._event(now, "mode", "center mode requested (CMR): awaiting local operator")
            return Reason.NONE
        if kind is F.LMQ:
            if value and self.modes.mode is Mode.CENTER and self.modes.to_local():
                self._event(now, "mode", "CTC handed the station back to local mode")
            return Reason.NONE
        wanted = Mode.CENTER if source == kinds.CTC else Mode.LOCAL
        if self.modes.mode is not wanted:
            return Reason.NOT_IN_CENTER_MODE
        if kind in (F.RSC, F.RCC):
            if not value:
                return Reason.NONE
            if kind is F.RCC:
                return self._cancel_route(obj, now)
            return self._request_route(obj, now, wait=source == kinds.CTC)
        if kind is F.DRC:
            if not value:
                return Reason.NONE
            return self._ask(obj, now)
        if kind in (F.SNC, F.SRC):
            if not value:
                return Reason.NONE
            return self._move_point(obj, "normal" if kind is F.SNC else "reverse", now)
        if kind is F.SSC:
            sig = self.signals[obj]
            if sig.stop_held != bool(value):
                sig.stop_held = bool(value)
                held = "held at stop" if value else "released from stop"
                self._event(now, "signal", f"signal {obj} {held} by the CTC")
            return Reason.NONE
        return Reason.UNKNOWN_CODE  # pragma: no cover - every chart control is handled above

    def startup_locked(self, element: str) -> bool:
        """A track circuit or point still held by start-up locking."""
        return element in self.startup_held

    def _holder_of(self, element: str, point: bool) -> RouteState | None:
        for rs in self.routes.values():
            if element in (rs.held_points if point else rs.held_tcs):
                return rs
        return None

    def _set_route(self, name: str, now: float, check_only: bool = False) -> Reason:
        """Check and lock route `name`; `check_only`: check only (the direction last)."""
        rs = self.routes[name]
        r = rs.route
        if rs.status in (RouteStatus.SETTING, RouteStatus.SET):
            return Reason.NONE
        if rs.status is not RouteStatus.IDLE:
            return Reason.ROUTE_CONFLICTS
        for other in r.conflicts:
            if self.routes[other].whole:
                self._event(now, "route", f"route {name} refused: conflicts with route {other}")
                return Reason.ROUTE_CONFLICTS
        handover: dict[str, RouteState] = {}  # our elements held as the overlap of a route into us
        onward_holds: set[str] = set()  # our overlap, already held by the route from our exit
        elements = [(tc, False) for tc in r.all_track_circuits]
        elements += [(s.point, True) for s in r.all_points]
        for element, is_point in elements:
            if element in self.startup_held:
                self._event(now, "route", f"route {name} refused: {element} start-up locked")
                return Reason.ROUTE_CONFLICTS
            holder = self._holder_of(element, point=is_point)
            if holder is None:
                continue
            if onward(holder.route, r) and element in holder.overlap_elements:
                handover[element] = holder
            elif onward(r, holder.route) and element in rs.overlap_elements:
                onward_holds.add(element)
            else:
                self._event(now, "route", f"route {name} refused: {element} locked")
                return Reason.ROUTE_CONFLICTS
        for tc in r.all_track_circuits:
            if self.occupied(tc):
                self._event(now, "route", f"route {name} refused: {tc} occupied")
                return Reason.TRACK_OCCUPIED
        for s in r.all_points:
            if self.detection(s.point) == "none":
                self._event(now, "route", f"route {name} refused: point {s.point} failed")
                return Reason.POINT_FAILED
        iv = self.view.interval_of_exit(r)
        if iv is not None:
            end = self.ends[iv.name]
            if end.boundary and not end.take_boundary(self._facts(iv)):
                self._event(now, "route", f"route {name} refused: interval {iv.name} occupied")
                return Reason.TRACK_OCCUPIED
            if not end.holds and not self.direction_check_disabled_for_tests:
                if not check_only:
                    self._event(now, "route", f"route {name} refused: no permission for {iv.name}")
                return Reason.DIRECTION
        if check_only:
            return Reason.NONE
        rs.lock()
        if onward_holds:
            rs.cede_overlap(rs.overlap_elements)
        for holder in {id(h): h for h in handover.values()}.values():
            holder.cede_overlap(holder.overlap_elements)
            self._event(now, "route", f"route {name} takes over the overlap of {holder.route.name}")
        self._event(now, "route", f"route {name} locked")
        return Reason.NONE

    def _request_route(self, name: str, now: float, wait: bool) -> Reason | None:
        """Set a route; a departure into an interval whose permission we lack asks for it and
        waits (None) when every other check passes now. From the local panel (`wait` False) it
        asks and is refused at once: the operator sets it again once the permission is here."""
        iv = self.view.interval_of_exit(self.routes[name].route)
        end = self.ends[iv.name] if iv is not None else None
        if end is None or end.boundary or end.holds or self.direction_check_disabled_for_tests:
            return self._set_route(name, now)
        if self.routes[name].status is not RouteStatus.IDLE:
            return self._set_route(name, now)  # already set or in use: answered as ever
        reason = self._set_route(name, now, check_only=True)
        if reason is not Reason.DIRECTION:
            return reason
        asked = self._ask(end.interval.name, now) is Reason.NONE
        return None if asked and wait else Reason.DIRECTION

    def _ask(self, interval: str, now: float) -> Reason:
        """Ask the neighbour for the interval's permission (DRC, or a departure wanting it)."""
        end = self.ends.get(interval)
        if end is None:
            return Reason.UNKNOWN_CODE  # pragma: no cover - DRC exists for our intervals only
        if end.ask(now):
            return Reason.NONE
        self._event(now, "route", f"interval {interval}: permission cannot be asked "
                    f"({'link down' if not end.link_up else end.holding.value})")  # fmt: skip
        return Reason.DIRECTION

    def _wait(self, interval: str, name: str, source: str, now: float) -> None:
        """A departure (control `name`) waits for the permission of the interval it leads to."""
        code = self.codes.parse_code(name)
        assert code is not None
        iv = self.view.interval_of_exit(self.routes[code.object].route)
        assert iv is not None
        self._waiting[iv.name].append((code.object, name, source))
        self._event(now, "control", f"{source}: {name}=1 waits for the permission of {iv.name}")

    def _answer_waiting(self, now: float) -> None:
        """Departures waiting for a permission: set once it is ours, refused once it cannot
        come."""
        for iv, waits in self._waiting.items():
            if not waits:
                continue
            end = self.ends[iv]
            if end.holding is Holding.ASKING:
                continue
            self._waiting[iv] = []
            for route, name, source in waits:
                reason = self._set_route(route, now) if end.holds else Reason.DIRECTION
                verdict = "accepted" if reason is Reason.NONE else f"rejected: {reason.text}"
                self._event(now, "control", f"{source}: {name}=1 {verdict}")
                self._results.append(ControlResult(name, reason is Reason.NONE, reason, late=True))

    def _cancel_route(self, name: str, now: float) -> Reason:
        rs = self.routes[name]
        if rs.status is RouteStatus.IDLE or rs.release_at is not None:
            return Reason.NONE
        if rs.status is RouteStatus.ENTERED:
            # A route the train has stopped inside: time-release what it still holds.
            if any(self.occupied(tc) for tc in rs.held_tcs):
                return Reason.TRACK_OCCUPIED
            self._start_timed_release(rs, now)
            return Reason.NONE
        approached = any(self.occupied(tc) for tc in rs.route.approach)
        if rs.cleared_once and approached:
            self._start_timed_release(rs, now)
        else:
            rs.release_all()
            self._event(now, "route", f"route {name} cancelled and released")
        return Reason.NONE

    def _start_timed_release(self, rs: RouteState, now: float) -> None:
        if rs.status is not RouteStatus.ENTERED:
            rs.status = RouteStatus.CANCELLING
        rs.release_at = now + rs.route.approach_release_s
        self._event(
            now,
            "route",
            f"route {rs.route.name} cancelled: approach locked, release in "
            f"{rs.route.approach_release_s:g} s",
        )

    def _move_point(self, name: str, position: PointPosition, now: float) -> Reason:
        ps = self.points[name]
        if self._holder_of(name, point=True) is not None or name in self.startup_held:
            return Reason.POINT_LOCKED
        if any(self.occupied(tc) for tc in ps.point.track_circuits):
            return Reason.TRACK_OCCUPIED
        if ps.demanded != position:
            ps.call(position)
            self._event(now, "point", f"point {name} commanded {position}")
        return Reason.NONE

    # ------------------------------------------------------------------ inputs

    def _apply_input(self, link: str, name: str, state: int, now: float) -> None:
        code = self.codes.parse_code(name)
        assert code is not None  # every name of the link's chart has a meaning
        kind, obj = code.function, code.object
        if link in self.neighbours:
            self.ends[self.neighbours[link]].receive(kind, state, now)
            return
        if kind is F.TC:
            self.tc_reports[link][name] = state
            return
        if link == kinds.ATC:
            if kind is F.IZC:
                self.izc[obj] = state
            elif kind is F.TTC:
                self.ttc[name] = state
            return
        if kind in BITS:
            self.points[obj].bits[kind.value] = state
            self.points[obj].answered = True
        elif kind is F.LFI:
            sig = self.signals[obj]
            if sig.lamp_failed != bool(state):
                sig.lamp_failed = bool(state)
                if state:
                    self._event(now, "fault", f"signal {obj}: lamp failure reported")
        elif kind is F.LPS:
            lamp = self.signals[obj]
            lamp.lamp_bits[code.aspect] = state
            lamp.lamp_reported = True

    def _facts(self, iv: Interval) -> Facts:
        """What this IXL knows of interval `iv` now (`ixl.direction.Facts`)."""
        end = self.ends[iv.name]
        clear = self.link_up[kinds.ATC] and self.izc.get(iv.name, 1) == 0
        clear = clear and not any(self.occupied(tc) for tc in self.view.owned_half(iv))
        if end.linked and end.peer_has_ttc:
            clear = clear and end.synced and end.peer.get(F.TTC, 1) == 0
        locked = any(
            self.routes[r].status is not RouteStatus.IDLE or self.routes[r].holds_anything
            for r in self._departures[iv.name]
        )
        return Facts(clear, locked, self._transit[iv.name])

    def _follow_transit(self, iv: Interval, facts: Facts) -> None:
        """A train of ours entered the interval (its half occupied under our entered departure);
        it has arrived when it was seen in the far half (the neighbour's TTC) and the whole
        interval is clear again -- where no neighbour reports a half, when it is clear."""
        name = iv.name
        entered = any(self.routes[r].status is RouteStatus.ENTERED for r in self._departures[name])
        if entered and any(self.occupied(tc) for tc in self.view.owned_half(iv)):
            if not self._transit[name]:
                self._transit[name], self._far_seen[name] = True, False
        end = self.ends[name]
        if not self._transit[name]:
            return
        far = end.linked and end.peer_has_ttc
        if far and end.peer.get(F.TTC) == 1:
            self._far_seen[name] = True
        if facts.clear and (self._far_seen[name] or not far):
            self._transit[name] = False

    # ------------------------------------------------------------------ evaluation

    def _finish(self, now: float) -> IxlOutput:
        self._evaluate(now)
        out = IxlOutput(results=self._results, events=self._events)
        for kind in self.outputs:
            state = self.full_state(kind)
            last = self._sent[kind]
            changes = [(k, v) for k, v in state.items() if last.get(k) != v]
            if changes:
                out.changes[kind] = changes
            self._sent[kind] = state
        self._results, self._events = [], []
        return out

    def _evaluate(self, now: float) -> None:
        if self.modes.handle_timer(now):
            self._event(now, "mode", "center mode granted automatically")
        live = self._reports_live()
        if self.startup_held and live:
            self._startup_release(now)
        # a permission just received sets its waiting departures before the rules may give it
        # away again; an ask that failed in this step is answered in it
        self._answer_waiting(now)
        for iv in self.intervals.values():
            facts = self._facts(iv)
            self._follow_transit(iv, facts)
            for note in self.ends[iv.name].step(self._facts(iv), now):
                self._event(now, "route", f"interval {iv.name}: {note}")
        self._answer_waiting(now)
        for rs in self.routes.values():
            if rs.release_at is not None:
                if now >= rs.release_at:
                    self._event(now, "route", f"route {rs.route.name} released (timed release)")
                    rs.release_all()
            if rs.status is RouteStatus.SET and live:
                self._detect_entry(rs, now)
            if rs.status is RouteStatus.ENTERED and live:
                self._sequential_release(rs, now)
                self._overlap_release(rs, now)
            if rs.status in (RouteStatus.SETTING, RouteStatus.SET):
                self._drive_points(rs, now)
        for rs in self.routes.values():  # after every release of this input: no gap between
            if rs.overlap_ceded and rs.holds_anything:
                self._retake_overlap(rs, now)
        self._update_signals(now)
        if live:
            self._occupied_before = {tc: self.occupied(tc) for tc in self.tc_names}

    def _startup_release(self, now: float) -> None:
        """Start-up locking ends: the station seen clear, or its time run out."""
        if not any(self.occupied(tc) for tc in self.tc_names):
            why = "the station is clear"
        elif self.startup_release_at is None:
            self.startup_release_at = now + self.startup_release_s
            self._event(now, "route", "start-up: a track circuit is occupied; every point and "
                        f"track circuit stays locked for {self.startup_release_s:g} s")  # fmt: skip
            return
        elif now >= self.startup_release_at:
            why = "timed release"
        else:
            return
        self.startup_held.clear()
        self.startup_release_at = None
        self._event(now, "route", f"start-up locking released ({why})")

    def _retake_overlap(self, rs: RouteState, now: float) -> None:
        """The onward route let our overlap go (cancelled or released): lock it again if free."""
        elements = rs.overlap_elements
        for other in self.routes.values():
            if other is not rs and (elements & (other.held_tcs | other.held_points)):
                return
        rs.take_back_overlap()
        self._event(now, "route", f"route {rs.route.name}: overlap locked again")

    def _overlap_locked(self, rs: RouteState) -> bool:
        """Our overlap is held by us, or by the onward route from our exit signal."""
        for element in rs.overlap_elements:
            if element in rs.held_tcs or element in rs.held_points:
                continue
            holder = self._holder_of(element, point=element in self.points)
            if holder is None or holder.route.entry != rs.route.exit:
                return False
        return True

    def _reports_live(self) -> bool:
        """Occupancy comes from live reports, not from the fail-safe assumption of a dead link or
        of a link back up whose peer has not yet reported every track circuit again."""
        return all(
            self.link_up[src] and len(self.tc_reports[src]) == len(self.tc_names)
            for src in self.tc_sources
        )

    def _was_occupied(self, tcs: tuple[str, ...]) -> bool:
        """Any of `tcs` occupied at the last evaluation with live reports."""
        return any(self._occupied_before.get(tc, True) for tc in tcs)

    def _detect_entry(self, rs: RouteState, now: float) -> None:
        """Called with live reports only: a dead link is never read as a train entering."""
        r = rs.route
        first = r.release_sections[0]
        if not any(self.occupied(tc) for tc in first):
            self._noticed.discard(r.name)
            return
        if self._proceed_before.get(r.entry, False):
            rs.status = RouteStatus.ENTERED
            self._event(now, kinds.TRAIN, f"train entered route {r.name}: signal {r.entry} to stop")
            rs.passed[0] = not r.approach or self._was_occupied(r.approach)
            if not rs.passed[0]:
                self._event(
                    now,
                    "fault",
                    f"route {r.name}: {'+'.join(first)} occupied with the approach "
                    f"{'+'.join(r.approach)} clear: not a train's sequence, the route stays "
                    "locked until it is cancelled (timed release)",
                )
        elif r.name not in self._noticed:
            self._noticed.add(r.name)
            self._event(now, "fault", f"route {r.name}: {first[0]} occupied, signal at stop")

    def _sequential_release(self, rs: RouteState, now: float) -> None:
        """Release by train passage, read from live reports only (SPEC §6.2).

        A section counts as passed when it went occupied while the track before it (the section
        before, itself passed, or the approach for the first) was already occupied at the
        previous live evaluation: the train's head running in. It is released once the track
        before it has cleared (the tail has followed: for the first section the approach, seen
        clear while the section was occupied or clear now; for the others the section before,
        released already) and it clears while the next section, itself passed, is occupied (the
        last section: when it clears). A train standing in the approach while the sections go
        occupied and clear around it has passed nothing.
        Track circuits that go occupied in one report and clear in one report (a rails outage, a
        detection failure, a failed-occupied track circuit that recovers) never make this
        sequence: such a route keeps everything locked until it is cancelled, which time-releases
        it with its approach-locking time.
        """
        r = rs.route
        sections = r.release_sections
        last = len(sections) - 1
        occupied = [any(self.occupied(tc) for tc in sec) for sec in sections]
        for k in range(rs.next_section, len(sections)):
            before = sections[k - 1] if k else r.approach
            ran_in = not before or self._was_occupied(before)  # no approach: the signal alone
            in_order = k == 0 or rs.passed[k - 1]  # the head runs in section after section
            if occupied[k] and not self._was_occupied(sections[k]) and ran_in and in_order:
                rs.passed[k] = True
        if rs.passed[0] and occupied[0] and not any(self.occupied(tc) for tc in r.approach):
            rs.approach_left = True
        while rs.next_section <= last:
            k = rs.next_section
            # the tail has followed: the approach seen clear behind the train in section 0, or
            # clear now (two joints crossed between reports); section k-1 released: it cleared
            tail_in = k > 0 or rs.approach_left or not any(self.occupied(tc) for tc in r.approach)
            onward = k == last or (rs.passed[k + 1] and occupied[k + 1])
            if not (rs.passed[k] and tail_in and not occupied[k] and onward):
                break
            rs.release_section(k, self._points_in)
            rs.next_section += 1
            self._event(now, "route", f"route {r.name}: {'+'.join(sections[k])} released")
        if rs.overlap_held and rs.overlap_at is None and rs.next_section <= last:
            if rs.passed[last]:  # the train reached the berth: it stops within the overlap
                rs.overlap_at = now + r.overlap_release_s

    def _overlap_release(self, rs: RouteState, now: float) -> None:
        """The overlap goes with the last section, or on its timer; then the route is free."""
        if rs.overlap_held:
            if rs.next_section >= len(rs.route.release_sections):
                rs.release_overlap()
            elif rs.overlap_at is not None and now >= rs.overlap_at:
                rs.release_overlap()
                self._event(now, "route", f"route {rs.route.name}: overlap released")
        if rs.next_section >= len(rs.route.release_sections) and not rs.overlap_held:
            rs.release_all()
            self._event(now, "route", f"route {rs.route.name} fully released")

    def _drive_points(self, rs: RouteState, now: float) -> None:
        """Demand every point of the route in its position; SET once all are detected there.

        The demand is corrected even where detection already agrees: a point still demanded the
        other way (an earlier individual control) would otherwise start moving under the route.
        """
        in_place = True
        for s in rs.route.all_points:
            ps = self.points[s.point]
            if ps.demanded != s.position:
                in_place = False
                if not any(self.occupied(tc) for tc in ps.point.track_circuits):
                    ps.call(s.position)
                    self._event(now, "point", f"point {s.point} commanded {s.position}")
            if self.detection(s.point) != s.position:
                in_place = False
        if in_place and rs.status is RouteStatus.SETTING:
            rs.status = RouteStatus.SET
            self._event(now, "route", f"route {rs.route.name} set: points detected")

    def proceed_conditions(self, route: Route) -> list[str]:
        """Why the route's signal may not show proceed now (empty: it may)."""
        rs = self.routes[route.name]
        why: list[str] = []
        if rs.status is not RouteStatus.SET:
            why.append(f"route {rs.status.value}")
        for link in LINKS:
            if not self.link_up[link]:
                why.append(f"{link} link down")
        for s in route.all_points:
            if self.detection(s.point) != s.position:
                why.append(f"point {s.point} not detected {s.position}")
            if self.points[s.point].demanded != s.position:
                why.append(f"point {s.point} not demanded {s.position}")
        if not self.occupancy_check_disabled_for_tests:
            why += [f"{tc} occupied" for tc in route.all_track_circuits if self.occupied(tc)]
        if not self._overlap_locked(rs):
            why.append("overlap not locked")
        iv = self.view.interval_of_exit(route)
        if iv is not None and not self.ends[iv.name].holds:
            if not self.direction_check_disabled_for_tests:
                why.append(f"interval {iv.name}: no traffic permission")
        if self.signals[route.entry].stop_held:
            why.append("held at stop")
        return why

    def _update_signals(self, now: float) -> None:
        ready: dict[str, Route] = {}
        for rs in self.routes.values():
            if rs.status is RouteStatus.SET and not self.proceed_conditions(rs.route):
                ready[rs.route.entry] = rs.route
        done: dict[str, str] = {}

        def aspect_of(signal: str, depth: int = 0) -> str:
            if signal in done:
                return done[signal]
            route = ready.get(signal)
            if route is None or depth > len(self.signals):
                done[signal] = "R"
                return "R"
            exit_shows = aspect_of(route.exit, depth + 1) if route.exit in self.signals else None
            sig = self.signals[signal].signal
            done[signal] = fit(sig, downgrade(route.aspect, exit_shows))
            return done[signal]

        for name, sig in self.signals.items():
            aspect = aspect_of(name)
            if aspect != sig.commanded:
                sig.commanded = aspect
                self._event(now, "signal", f"signal {name} {aspect}")
            if aspect != "R":
                self.routes[ready[name].name].cleared_once = True
            self._proceed_before[name] = aspect != "R"

    # ------------------------------------------------------------------ output states

    def _ctc_state(self) -> dict[str, int]:
        names = self._names
        loc, ctc, cmr = names.mode
        out = {
            loc: int(self.modes.mode is Mode.LOCAL),
            ctc: int(self.modes.mode is Mode.CENTER),
            cmr: int(self.modes.requested),
        }
        locked = {p for rs in self.routes.values() for p in rs.held_points}
        locked |= self.startup_held & set(self.points)
        for name, (sni, srn, sri, snr, sli, sfi) in names.ctc_points.items():
            det = self.detection(name)
            out[sni] = int(det == "normal")
            out[srn] = int(det == "to_normal")
            out[sri] = int(det == "reverse")
            out[snr] = int(det == "to_reverse")
            out[sli] = int(name in locked)
            out[sfi] = int(det == "none")
        io_up = self.link_up[kinds.IO]
        for sig, aspects, ssi, lfi in names.ctc_signals:
            shown = sig.shown() if io_up else "R"
            for a, asp in aspects:
                out[asp] = int(shown == a)
            out[ssi] = int(sig.stop_held)
            out[lfi] = int(sig.lamp_failed)
        for tc in self.tc_names:
            out[tc] = int(self.occupied(tc))
        for rs, rsi, ali in names.ctc_routes:
            out[rsi] = int(rs.status is not RouteStatus.IDLE)
            out[ali] = int(rs.release_at is not None)
        self._directions(out)
        for end, phi, prq in names.permissions:
            out[phi] = end.phi
            out[prq] = end.prq
        return out

    def _directions(self, out: dict[str, int]) -> None:
        """TDU/TDD follow the permission: the holder's departure direction; both 0 while
        nobody holds it, as far as this IXL knows."""
        for end, tdu, tdd in self._names.directions:
            d = end.direction
            out[tdu] = int(d == "up")
            out[tdd] = int(d == "down")

    def _neighbour_state(self, interval: str) -> dict[str, int]:
        """What this IXL tells the neighbour of their interval (its IXL->ROLE chart)."""
        end, iv = self.ends[interval], self.intervals[interval]
        phi, prq, drl = self._names.neighbour[interval]
        out = {phi: end.phi, prq: end.prq}
        out[drl] = int(self._facts(iv).departure_locked)
        for ttc in self.codes.totalisers:
            if ttc.interval == interval:
                out[ttc.name] = int(any(self.occupied(tc) for tc in ttc.track_circuits))
        return out

    def _atc_state(self) -> dict[str, int]:
        names = self._names
        out = {rli: int(rs.whole) for rs, rli in names.atc_routes}
        for name, (sni, sri) in names.atc_points.items():
            det = self.detection(name)
            out[sni] = int(det == "normal")
            out[sri] = int(det == "reverse")
        proceed_ok = self.link_up[kinds.IO]
        for sig, sgp in names.atc_signals:
            out[sgp] = int(sig.proceed and proceed_ok)
        self._directions(out)
        return out

    def _io_state(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for ps, pnc, prc in self._names.io_points:
            out[pnc] = int(ps.demanded == "normal")
            out[prc] = int(ps.demanded == "reverse")
        for sig, aspects in self._names.io_signals:
            for a, sgc in aspects:
                out[sgc] = int(sig.commanded == a)
        return out

    def _event(self, now: float, kind: str, text: str) -> None:
        ev = IxlEvent(now, kind, text)
        self._events.append(ev)
        self.log.append(ev)
        if len(self.log) > self._log_limit:
            del self.log[: len(self.log) - self._log_limit]


class _OutputNames:
    """The code names of an IXL's output states, formatted once with the objects they tell of
    (the outputs are built at every evaluation: formatting each name there cost more than the
    interlocking's logic). In the order the states list them."""

    def __init__(self, ixl: Interlocking) -> None:
        st = ixl.st
        self.mode = (n.loc(st), n.ctc(st), n.cmr(st))
        self.ctc_points = {
            p: (n.sni(st, p), n.srn(st, p), n.sri(st, p), n.snr(st, p), n.sli(st, p), n.sfi(st, p))
            for p in ixl.points
        }
        self.ctc_signals = [
            (
                sig,
                tuple((a, n.asp(st, name, a)) for a in sig.signal.aspects),
                n.ssi(st, name),
                n.lfi(st, name),
            )
            for name, sig in ixl.signals.items()
        ]
        self.ctc_routes = [(rs, n.rsi(st, r), n.ali(st, r)) for r, rs in ixl.routes.items()]
        self.permissions = [(end, n.phi(iv), n.prq(iv)) for iv, end in ixl.ends.items()]
        self.directions = [(end, n.tdu(iv), n.tdd(iv)) for iv, end in ixl.ends.items()]
        self.neighbour = {iv: (n.phi(iv), n.prq(iv), n.drl(iv)) for iv in ixl.neighbours.values()}
        self.atc_routes = [(rs, n.rli(st, r)) for r, rs in ixl.routes.items()]
        self.atc_points = {p: (n.sni(st, p), n.sri(st, p)) for p in ixl.points}
        self.atc_signals = [(sig, n.sgp(st, name)) for name, sig in ixl.signals.items()]
        self.io_points = [(ps, n.pnc(st, p), n.prc(st, p)) for p, ps in ixl.points.items()]
        self.io_signals = [
            (sig, tuple((a, n.sgc(st, name, a)) for a in sig.signal.aspects))
            for name, sig in ixl.signals.items()
        ]
