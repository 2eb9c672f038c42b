"""A station on the bench without links: one Interlocking wired straight to its Trackside.

For deterministic virtual-time runs and tests: code changes pass between the two objects at once
(as over a perfect Type I link) and track occupancy is fed as the ATC would report it. The rig is
one `Timed` core (`ktcs_bench.timed`): `next_deadline()` is the earlier of the two cores',
`handle_timer(now)` runs both and returns the interlocking's new events; `advance` walks it
through virtual time on the virtual clock, and a wall-clock driver can run it as well (the
console's demo stations). `ctc` is the CTC's picture, kept by the IXL->CTC changes, which are
also handed to `on_ctc` as they come (a Type II link to a real CTC). With `neighbour_links` the
interlocking is linked with neighbouring IXLs (SPEC §6.6): what it tells each is gathered in
`to_neighbour[role]` for whoever carries it across (`deliver` hands codes in), and a departure
waiting for an interval's permission is answered later, into `results`. No I/O, no clock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

from ktcs_bench import kinds
from ktcs_bench.field.trackside import Trackside
from ktcs_bench.ixl.interlocking import ControlResult, Interlocking, IxlEvent, IxlOutput
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.station.model import StationView
from ktcs_bench.station_codes import names as n
from ktcs_bench.timed.virtual import VirtualClock


class StationRig:
    def __init__(
        self,
        view: StationView,
        *,
        mode: Mode = Mode.CENTER,
        now: float = 0.0,
        occupied: Iterable[str] = (),
        startup_locking: bool = False,
        neighbour_links: Iterable[str] = (),
    ) -> None:
        """`occupied`: track circuits with a train in them when the interlocking starts;
        `startup_locking`: it starts as one restarted in a running railway; `neighbour_links`:
        the neighbouring IXLs it is linked with (their links start down: `set_link`)."""
        self.view = view
        self.now = now
        self._mode = mode
        self._neighbour_links = tuple(neighbour_links)
        self.results: list[ControlResult] = []  # answers that came later (a permission waited)
        self.io = Trackside(view)
        self.occupancy = {t.name: t.name in set(occupied) for t in view.track_circuits}
        self.io.set_occupancy(self.occupancy, now)
        self.events: list[IxlEvent] = []
        self.on_ctc: Callable[[list[tuple[str, int]]], None] | None = None
        self._start(startup_locking)

    def _start(self, startup_locking: bool) -> None:
        """A new interlocking, its ATC and trackside links brought up."""
        self.ixl = Interlocking(
            self.view,
            mode=self._mode,
            startup_locking=startup_locking,
            neighbour_links=self._neighbour_links,
        )
        self.to_neighbour: dict[str, list[tuple[str, int]]] = {r: [] for r in self.ixl.neighbours}
        self.ctc = self.ixl.full_state(kinds.CTC)  # the CTC's picture, kept by indication changes
        self.atc = self.ixl.full_state(kinds.ATC)  # what the ATC is told
        self.io.link_state(True, self.now)
        self.take(self.ixl.link_state(kinds.IO, True, self.now))
        self.take(self.ixl.link_state(kinds.ATC, True, self.now))
        self.take(self.ixl.receive(kinds.IO, self.io.full_state(), self.now))
        self._report_occupancy()

    def restart(self) -> None:
        """The interlocking crashes and a new one starts, as one restarted in a running railway
        (start-up locking): the trackside keeps its blades, faults and the demands it was last
        given until the new interlocking's link comes up and says otherwise: every code of its
        IXL->IO chart, as a Type I link's resync carries them."""
        self.io.link_state(False, self.now)
        self._start(startup_locking=True)
        self.from_field(self.io.receive(self.ixl.full_state(kinds.IO), self.now).changes)

    def control(self, name: str, value: int = 1) -> ControlResult:
        """A control answered at once (a departure that waits for a permission: `request`)."""
        result = self.request(name, value)
        if result is None:
            raise RuntimeError(f"{name} waits for an interval's permission: use request()")
        return result

    def request(self, name: str, value: int = 1) -> ControlResult | None:
        """A control; None while it waits for an interval's permission (its answer comes into
        `results`)."""
        out = self.ixl.control(name, value, self.now)
        result = next((r for r in out.results if not r.late), None)
        out.results = [r for r in out.results if r is not result]  # the rest came late
        self.take(out)
        return result

    def deliver(self, role: str, codes: Mapping[str, int]) -> None:
        """Codes from the neighbour `role` (as its link delivers them)."""
        self.take(self.ixl.receive(role, codes, self.now))

    def occupy(self, tc: str, occupied: bool = True) -> None:
        self.occupancy[tc] = occupied
        self.io.set_occupancy({tc: occupied}, self.now)
        self._report_occupancy()

    def set_link(self, link: str, up: bool) -> None:
        self.take(self.ixl.link_state(link, up, self.now))
        if link in self.ixl.neighbours:
            return  # its codes come from the neighbour (`deliver`)
        if link == kinds.IO:
            self.from_field(self.io.link_state(up, self.now).changes)
        if up:
            full = self.io.full_state() if link == kinds.IO else None
            if full is not None:
                self.take(self.ixl.receive(kinds.IO, full, self.now))
            else:
                self._report_occupancy(full=True)

    def next_deadline(self) -> float | None:
        """The earlier of the IXL's and the trackside's deadlines."""
        due = [d for d in (self.ixl.next_deadline(), self.io.next_deadline()) if d is not None]
        return min(due, default=None)

    def handle_timer(self, now: float) -> list[IxlEvent]:
        """Both cores' timers by `now` (the trackside first: a point that arrived is reported
        to the interlocking in the same instant); the interlocking's events of this call."""
        self.now = max(self.now, now)
        first = len(self.events)
        self.from_field(self.io.handle_timer(self.now).changes)
        self.take(self.ixl.handle_timer(self.now))
        return self.events[first:]

    def advance(self, seconds: float) -> None:
        """Move virtual time on, honouring every deadline of the IXL and the trackside."""
        end = self.now + seconds
        clock = VirtualClock(self.now)
        clock.add(self)
        clock.run_until(end)
        self.now = end

    def _report_occupancy(self, full: bool = False) -> None:
        codes = {tc: int(v) for tc, v in self.occupancy.items()}
        for iv in self.view.intervals:
            half = self.view.owned_half(iv)
            codes[n.izc(iv.name)] = int(any(self.occupancy[t] for t in half))
        self.take(self.ixl.receive(kinds.ATC, codes, self.now))

    def from_field(self, changes: list[tuple[str, int]]) -> None:
        if changes:
            self.take(self.ixl.receive(kinds.IO, dict(changes), self.now))

    def take(self, out: IxlOutput) -> None:
        self.events += out.events
        self.results += [r for r in out.results if r.late]
        for role, changes in self.to_neighbour.items():
            changes += out.of(role)
        ctc = out.of(kinds.CTC)
        self.ctc.update(ctc)
        if ctc and self.on_ctc is not None:
            self.on_ctc(ctc)
        self.atc.update(out.of(kinds.ATC))
        if io := out.of(kinds.IO):
            self.from_field(self.io.receive(dict(io), self.now).changes)
