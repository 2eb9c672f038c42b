"""The trackside I/O rack of one station (kind `trackside`): the far end of the IXL's Type I link
with link role `io` (`ktcs_bench.kinds`).

Inputs by IXL->IO code name (`receive`), train occupancy from the track-circuit model
(`set_occupancy`), link state and `now`; outputs the IO->IXL code changes -- and a point's four
indications whenever it is called (PNC/PRC received), changed or not: the answer the interlocking
waits for before it believes where a call left the blades (`ixl.points`). When its link to the
IXL is in communication error the rack puts every signal to stop (the vital outputs drop) and
leaves the points where they are. When the rails (the source of train occupancy) are lost
(`rails_state(False)`) every track relay reports occupied, whatever it last knew or its faults,
until the rails are back and report it again. Its one timer is the point machines' throw:
`handle_timer(now)` at `next_deadline()` (the timer shape of every core, `ktcs_bench.timed`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ktcs_bench.field import points as point_faults
from ktcs_bench.field import relays as relay_faults
from ktcs_bench.field.points import PointMachine
from ktcs_bench.field.relays import TrackRelay
from ktcs_bench.field.signals import SignalHead
from ktcs_bench.station.model import StationView
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.names import Function as F
from ktcs_bench.station_codes.stations import StationCodes


@dataclass(frozen=True, slots=True)
class FieldEvent:
    time: float
    kind: str  # point, signal, fault, link, rails
    text: str


@dataclass
class FieldOutput:
    changes: list[tuple[str, int]] = field(default_factory=list)  # IO->IXL code changes
    events: list[FieldEvent] = field(default_factory=list)


class Trackside:
    def __init__(self, view: StationView) -> None:
        self.view = view
        self.st = view.number
        self.points = {p.name: PointMachine(p) for p in view.station.points}
        self.signals = {s.name: SignalHead(s) for s in view.station.lamp_signals}
        self.relays = {t.name: TrackRelay(t.name) for t in view.track_circuits}
        self.link_up = False
        self.rails_up = True  # the occupancy source is there (an adapter with rails says when not)
        self._sgc: dict[str, dict[str, int]] = {s: {} for s in self.signals}
        self._demand: dict[str, tuple[int, int]] = {p: (1, 0) for p in self.points}
        self.codes = StationCodes(view)
        self._command_names = self.codes.names("ixl_to_io")
        self._events: list[FieldEvent] = []
        self.log: list[FieldEvent] = []
        self._sent = self.full_state()

    # ------------------------------------------------------------------ inputs

    def receive(self, codes: Mapping[str, int], now: float) -> FieldOutput:
        """IXL->IO code changes (or a full state): point demands PNC/PRC, lamp commands SGC."""
        touched: set[str] = set()
        moved: set[str] = set()  # points acted on once the whole message is read
        for name, state in codes.items():
            code = self.codes.parse_code(name)
            kind, obj = (code.function, code.object) if code is not None else (None, "")
            if kind in (F.PNC, F.PRC) and obj in self.points:
                demand = (
                    int(state) if kind is F.PNC else self._level(obj, "PNC"),
                    int(state) if kind is F.PRC else self._level(obj, "PRC"),
                )
                self._demand[obj] = demand
                moved.add(obj)
            elif kind is F.SGC and obj in self.signals and code is not None:
                self._sgc[obj][code.aspect] = int(state)
                touched.add(obj)
            else:
                self._event(now, "fault", f"unknown command {name!r} ignored")
        called: set[str] = set()  # each answered with its indications (`_finish`)
        for p in sorted(moved):
            if self._demand[p] == (1, 0):
                self._throw(p, "normal", now)
                called.add(p)
            elif self._demand[p] == (0, 1):
                self._throw(p, "reverse", now)
                called.add(p)
        if self.link_up:
            for s in touched:
                self.signals[s].command_bits(self._sgc[s])
        return self._finish(now, answered=called)

    def set_occupancy(self, occupied: Mapping[str, bool], now: float) -> FieldOutput:
        """Train occupancy per track circuit (from the track-circuit model); others unchanged.
        Ignored while the rails are lost."""
        for name, occ in occupied.items():
            relay = self.relays.get(name)
            if relay is not None and self.rails_up:
                relay.train = bool(occ)
        return self._finish(now)

    def rails_state(self, up: bool, now: float) -> FieldOutput:
        """The rails lost or back. Lost: every track relay occupied until reported again."""
        if up != self.rails_up:
            self.rails_up = up
            if up:
                self._event(now, "rails", "rails back: track relays as the rails report them")
            else:
                for relay in self.relays.values():
                    relay.train = True  # unknown = occupied
                self._event(now, "rails", "rails lost: every track circuit occupied")
        return self._finish(now)

    def link_state(self, up: bool, now: float) -> FieldOutput:
        if up != self.link_up:
            self.link_up = up
            if up:
                self._event(now, "link", "IXL link up")
                for s, sig in self.signals.items():
                    sig.command_bits(self._sgc[s])
            else:
                self._event(now, "link", "IXL link in communication error: all signals to stop")
                for sig in self.signals.values():
                    sig.commanded = "R"
        return self._finish(now)

    def handle_timer(self, now: float) -> FieldOutput:
        """A point throw due by `now` ends (call at or after `next_deadline()`)."""
        return self._finish(now)

    # ------------------------------------------------------------------ faults

    def fail_point(self, point: str, kind: str, now: float) -> FieldOutput:
        """Inject a point fault: "detection" (indication lost), "jammed" (never arrives) or
        "crossed" (detection reports the other end position: wrong-side)."""
        if kind not in point_faults.FAULTS:
            raise ValueError(f"unknown point fault {kind!r} {point_faults.FAULTS}")
        self.points[point].fault = kind
        self._event(now, "fault", f"point {point}: {kind} fault injected")
        return self._finish(now)

    def trail(self, point: str, leg: str, now: float) -> FieldOutput:
        """A train trailed `point` from its `leg` (normal | reverse) against the blades: they
        are forced over, and its detection is lost until `clear_faults`."""
        pm = self.points[point]
        if leg not in ("normal", "reverse"):
            raise ValueError(f"point {point}: no {leg!r} leg")
        pm.trail("normal" if leg == "normal" else "reverse")
        self._event(now, "fault", f"point {point} trailed from its {leg} leg: detection lost")
        return self._finish(now)

    def blades(self) -> dict[str, str]:
        """Where each point's blades are (`PointMachine.blades`): what trains run by."""
        return {name: pm.blades() for name, pm in self.points.items()}

    def fail_lamp(self, signal: str, aspect: str, now: float) -> FieldOutput:
        sig = self.signals[signal]
        if aspect not in sig.signal.aspects:
            raise ValueError(f"signal {signal} has no {aspect!r} lamp")
        sig.failed.add(aspect)
        self._event(now, "fault", f"signal {signal}: {aspect} lamp failed")
        return self._finish(now)

    def fail_track_circuit(self, tc: str, kind: str, now: float) -> FieldOutput:
        """Inject "failed_occupied" or "failed_clear" (wrong-side) into a track relay."""
        if kind not in relay_faults.FAULTS:
            raise ValueError(f"unknown track fault {kind!r} {relay_faults.FAULTS}")
        self.relays[tc].fault = kind
        self._event(now, "fault", f"{tc}: relay {kind}")
        return self._finish(now)

    def clear_faults(self, now: float) -> FieldOutput:
        for p in self.points.values():
            p.fault = None
        for s in self.signals.values():
            s.failed.clear()
        for r in self.relays.values():
            r.fault = None
        self._event(now, "fault", "all faults cleared")
        return self._finish(now)

    # ------------------------------------------------------------------ queries

    def command_names(self) -> tuple[str, ...]:
        return self._command_names

    def next_deadline(self) -> float | None:
        due = [p.next_deadline() for p in self.points.values()]
        return min((d for d in due if d is not None), default=None)

    def full_state(self) -> dict[str, int]:
        """Every IO->IXL chart code: point indications, lamps, track relays."""
        st = self.st
        out: dict[str, int] = {}
        for name, pm in self.points.items():
            bits = pm.bits()
            out[n.sni(st, name)] = bits["SNI"]
            out[n.srn(st, name)] = bits["SRN"]
            out[n.sri(st, name)] = bits["SRI"]
            out[n.snr(st, name)] = bits["SNR"]
        for name, sig in self.signals.items():
            lit = sig.lit()
            for a in sig.signal.aspects:
                out[n.lps(st, name, a)] = int(lit == a)
            out[n.lfi(st, name)] = int(sig.lamp_failure)
        for name, relay in self.relays.items():
            out[name] = int(relay.occupied or not self.rails_up)
        return out

    # ------------------------------------------------------------------ internals

    def _indications(self, point: str) -> tuple[str, str, str, str]:
        st = self.st
        return n.sni(st, point), n.srn(st, point), n.sri(st, point), n.snr(st, point)

    def _level(self, point: str, kind: str) -> int:
        pnc, prc = self._demand[point]
        return pnc if kind == "PNC" else prc

    def _throw(self, point: str, target: str, now: float) -> None:
        pm = self.points[point]
        if pm.command("normal" if target == "normal" else "reverse", now):
            self._event(now, "point", f"point {point} moving to {target}")

    def _finish(self, now: float, answered: set[str] | None = None) -> FieldOutput:
        """The code changes since the last output, and the indications of every point in
        `answered` (called in this input) even if unchanged: the answer to a call."""
        for name, pm in self.points.items():
            if pm.handle_timer(now):
                self._event(now, "point", f"point {name} detected {pm.position}")
        state = self.full_state()
        again = {c for p in answered or () for c in self._indications(p)}
        out = FieldOutput(
            changes=[(k, v) for k, v in state.items() if self._sent.get(k) != v or k in again],
            events=self._events,
        )
        self._sent = state
        self._events = []
        return out

    def _event(self, now: float, kind: str, text: str) -> None:
        ev = FieldEvent(now, kind, text)
        self._events.append(ev)
        self.log.append(ev)
