"""One end of an interval's traffic permission (SPEC §6.6), sans-I/O.

An interval between two stations is worked one direction at a time; its permission is held by at
most one of its two IXLs, and only the holder locks a departure route into it. `IntervalEnd` is
one IXL's end: fed the neighbour's codes (`receive`: PHI, PRQ, DRL and its TTC, by function), the
link's state (`link_state`), its own facts at each evaluation (`step`: the whole interval clear
as this end sees it, a departure route of its own into it locked, a train of its own in transit)
and `now`; it gives the codes to send (`phi`, `prq`), its decisions (`step`'s notes), whether a
departure may be locked (`holds`), the direction the interval is worked in as far as it knows
(`direction`) and a deadline (`next_deadline`: the 3 s an ask waits).

The rules, and why they keep at most one holder:
- The holder gives the permission only when the neighbour asks (PRQ) and the whole interval is
  clear, no departure route of its own into it is locked and no train of its own is in transit;
  it stops holding in the same step that makes its PHI 0, so it is never a holder after saying it
  is not. A PHI going 1 -> 0 on a live link is a gift only as the answer to an ask: the asker (or
  an end whose ask timed out at most `ASK_TIMEOUT_S` before, the gift on its way) becomes the
  holder when it reads that, never before, and only while the neighbour says no departure route
  of its own is locked and its half is clear (as a giver must). Any other PHI 1 -> 0 is a
  neighbour that forgot the permission (an IXL restarted and back before this end saw its link
  fail): nobody is taken to hold it, as after a resync that found neither end holding. The
  decision is made at the next evaluation, on everything the neighbour said by then.
- A link in communication error changes nothing hands: the holder keeps holding (and departing),
  the other end may not depart. What the neighbour said before the outage is forgotten, so no
  resync is read as a gift. An ask in flight fails.
- Resync (every neighbour code read again after the link came up): whoever says PHI 1 holds. If
  neither holds (a lost gift, both ends restarted, a first start), the default end (its departure
  direction is the interval's `default_direction`) takes it, once the whole interval is clear;
  until then nobody departs.
- An IXL restarted knows no permission (`UNKNOWN`) until its link has resynced.

Two degenerate ends need no neighbour: a boundary interval (a lab edge, no IXL beyond) whose one
IXL works it alone -- its direction is the default, except while a departure of its own runs out
through it -- and an interval whose neighbour link this IXL does not have (`linked=False`: a
single station on the bench), worked as if the default end held the permission for good.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from ktcs_bench.station.model import Direction, Interval, opposite
from ktcs_bench.station_codes.names import Function as F

ASK_TIMEOUT_S = 3.0
"""How long a departure waits for the neighbour's permission before it is refused."""

PEER_FUNCTIONS: tuple[F, ...] = (F.PHI, F.PRQ, F.DRL, F.TTC)
"""What a neighbour says of the interval (TTC only when it owns track circuits of it)."""


class Holding(StrEnum):
    HOLDER = "holder"
    NOT_HOLDER = "not holder"
    ASKING = "asking"
    UNKNOWN = "unknown"


@dataclass(frozen=True, slots=True)
class Facts:
    """What the IXL knows of the interval at one evaluation."""

    clear: bool
    """The whole interval clear as this end sees it: its own half, and the neighbour's TTC."""
    departure_locked: bool
    """A departure route of this IXL's into the interval is locked."""
    in_transit: bool
    """A train this IXL sent into the interval has not been seen to arrive."""


class IntervalEnd:
    """One IXL's end of one interval. See the module docstring."""

    def __init__(
        self, interval: Interval, station: int, *, linked: bool, peer_has_ttc: bool = True
    ) -> None:
        self.interval = interval
        self.station = station
        self.boundary = interval.boundary
        self.linked = linked and not interval.boundary
        self.departs: Direction = opposite(interval.toward(station))
        """The direction of a departure from this station into the interval."""
        self.default_end = interval.default_direction == self.departs
        self.peer_has_ttc = peer_has_ttc
        self._expected = len(PEER_FUNCTIONS) if peer_has_ttc else len(PEER_FUNCTIONS) - 1
        self.link_up = False
        self.peer: dict[F, int] = {}  # the neighbour's codes read since the link came up
        self.synced = False
        self.nobody = False  # resync found neither end holding
        self.peer_held = False  # the neighbour held it when last heard (kept over an outage)
        self.ask_until: float | None = None
        self.ask_ended: float | None = None  # when the last ask failed (a gift may still come)
        self.dropped: float | None = None  # when the neighbour's PHI went 1 -> 0, undecided
        self.running_out = False  # boundary: a departure of ours still in the interval
        self._notes: list[str] = []
        if self.linked:
            self.holding = Holding.UNKNOWN
        elif self.boundary:
            self.holding = Holding.NOT_HOLDER  # holds it only while a departure of ours runs
        else:
            self.holding = Holding.HOLDER if self.default_end else Holding.NOT_HOLDER
            self.peer_held = not self.default_end

    # ------------------------------------------------------------------ queries

    @property
    def holds(self) -> bool:
        return self.holding is Holding.HOLDER

    @property
    def phi(self) -> int:
        return int(self.holding is Holding.HOLDER)

    @property
    def prq(self) -> int:
        return int(self.holding is Holding.ASKING)

    @property
    def direction(self) -> Direction | None:
        """The direction the interval is worked in, as far as this end knows (None: nobody
        holds it, or it cannot know)."""
        if self.boundary:
            return self.departs if self.holds else self.interval.default_direction
        if self.holds:
            return self.departs
        if self.holding is not Holding.UNKNOWN and self.peer_held:
            return opposite(self.departs)
        return None

    def next_deadline(self) -> float | None:
        return self.ask_until

    # ------------------------------------------------------------------ inputs

    def link_state(self, up: bool, now: float) -> None:
        """The neighbour link came up or went into communication error."""
        if up == self.link_up or not self.linked:
            return
        self.link_up = up
        self.peer.clear()
        self.synced = False
        self.nobody = False
        if not up and self.holding is Holding.ASKING:
            self._end_ask("the neighbour link failed", now)

    def receive(self, function: F, state: int, now: float) -> None:
        """One of the neighbour's codes of this interval (PHI, PRQ, DRL, TTC)."""
        if not (self.linked and self.link_up):
            return
        before = self.peer.get(function)
        self.peer[function] = int(state)
        if not self.synced:
            if len(self.peer) >= self._expected:
                self._resync()
            return
        if function is F.PHI:
            if before == 1 and state == 0 and self.holding is not Holding.HOLDER:
                self.dropped = now  # a gift or not: decided at the next step, on all it said
            elif state == 1:
                self.dropped = None
                self.peer_held, self.nobody = True, False

    def ask(self, now: float) -> bool:
        """Ask the neighbour for the permission (a departure wants it). True: held already or
        asked now; False: it cannot be asked (no link, nothing known, nobody holds it)."""
        if self.holds or self.holding is Holding.ASKING:
            return True
        if self.boundary:
            return False
        if not (self.linked and self.link_up and self.synced and self.peer.get(F.PHI) == 1):
            return False
        self.holding = Holding.ASKING
        self.ask_until = now + ASK_TIMEOUT_S
        self._notes.append("permission asked of the neighbour")
        return True

    def step(self, facts: Facts, now: float) -> list[str]:
        """Apply the rules to this evaluation's facts; what was decided (for the log)."""
        if self.boundary:
            self._boundary(facts)
        elif self.linked:
            if self.dropped is not None:
                self._gift_or_forgotten(facts, self.dropped)
            if self.holding is Holding.ASKING and self.ask_until is not None:
                if now >= self.ask_until:
                    self._end_ask(f"no permission within {ASK_TIMEOUT_S:g} s", now)
            free = facts.clear and not facts.departure_locked and not facts.in_transit
            if self.holds and self.synced and self.link_up and self.peer.get(F.PRQ) == 1 and free:
                self.holding = Holding.NOT_HOLDER  # before the PHI 0 that says so goes out
                self.peer_held = False
                self._notes.append("permission given to the neighbour")
            if self.nobody and self.default_end and not self.holds and free and self.link_up:
                self.holding = Holding.HOLDER
                self.nobody = False
                self._notes.append("nobody held the permission: the default end takes it")
        notes, self._notes = self._notes, []
        return notes

    def take_boundary(self, facts: Facts) -> bool:
        """A boundary interval: a departure of ours may go into it if it runs our way already
        or the interval is clear (it then runs our way)."""
        if self.holds or self.departs == self.interval.default_direction:
            self.holding = Holding.HOLDER
            return True
        if facts.clear:
            self.holding = Holding.HOLDER
            self._notes.append(f"traffic direction now {self.departs} (our departure)")
            return True
        return False

    # ------------------------------------------------------------------ internals

    def _boundary(self, facts: Facts) -> None:
        """Our departure direction holds while a departure route of ours into it is locked or
        its train is still in it; then the interval's own direction again."""
        if not self.holds:
            return
        if facts.departure_locked or facts.in_transit or not facts.clear:
            return
        self.holding = Holding.NOT_HOLDER
        if self.departs != self.interval.default_direction:
            self._notes.append(f"traffic direction {self.interval.default_direction} again")

    def _resync(self) -> None:
        self.synced = True
        peer_holds = self.peer.get(F.PHI) == 1
        self.peer_held = peer_holds
        if self.holds:
            self._notes.append("link resynced: we hold the permission")
            return
        self.holding = Holding.NOT_HOLDER
        self.ask_until = None
        if peer_holds:
            self._notes.append("link resynced: the neighbour holds the permission")
        else:
            self.nobody = True
            self._notes.append("link resynced: neither end holds the permission")

    def _end_ask(self, why: str, now: float) -> None:
        self.holding = Holding.NOT_HOLDER
        self.ask_until = None
        self.ask_ended = now
        self._notes.append(f"ask failed: {why}")

    def _answers_an_ask(self, now: float) -> bool:
        """A PHI 1 -> 0 read now is the neighbour giving the permission: this end asked (or its
        ask failed so lately that the gift was on its way), and the neighbour says what a giver
        says -- no departure route of its own into the interval locked, its half clear."""
        asked = self.holding is Holding.ASKING or (
            self.ask_ended is not None and now - self.ask_ended <= ASK_TIMEOUT_S
        )
        quiet = self.peer.get(F.DRL) == 0 and (not self.peer_has_ttc or self.peer.get(F.TTC) == 0)
        return asked and quiet

    def _gift_or_forgotten(self, facts: Facts, dropped: float) -> None:
        """The neighbour's PHI went 1 -> 0 at `dropped`: read with everything else it said
        then (its DRL and TTC may come in the same message, after it), and this end's own
        picture of the interval, it is a gift or a neighbour that forgot the permission."""
        self.dropped = None
        if self.holding is Holding.HOLDER:
            return
        if self._answers_an_ask(dropped) and facts.clear and not facts.in_transit:
            self.holding = Holding.HOLDER
            self.ask_until = self.ask_ended = None
            self.peer_held = self.nobody = False
            self._notes.append("permission received from the neighbour")
        else:
            self._forgotten(dropped)

    def _forgotten(self, now: float) -> None:
        """The neighbour stopped holding without giving (a restart it came back from before
        this end saw its link fail): nobody holds it as far as this end knows, as after a
        resync that found neither end holding -- the default end takes it once the whole
        interval is clear."""
        if self.holding is Holding.ASKING:
            self._end_ask("the neighbour let the permission go without giving it", now)
        self.holding = Holding.NOT_HOLDER
        self.peer_held = False
        self.nobody = True
        self._notes.append("the neighbour let the permission go without giving it (restarted?): "
                           "nobody holds it")  # fmt: skip
