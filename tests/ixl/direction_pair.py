"""Two interlockings on the reference line, 18 and 20, linked across interval 1820 by hand.

Each station is a `StationRig` (its trackside wired straight in) whose interlocking is linked with
its neighbour; what one tells the other is carried across by `shuttle`, or lost (`drop`), as a
Type I link would carry it or lose it (a lost frame is followed by the link's communication error
and its resync: `link`). No I/O, no clock: virtual time moves on both rigs together.
"""

from __future__ import annotations

from ktcs_bench import kinds
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.model import Line

INTERVAL = "1820"


class Pair:
    """Stations 18 (west end of 1820: its `east` link) and 20 (its `west` link)."""

    def __init__(self, line: Line, *, up: bool = True) -> None:
        self.line = line
        self.west = StationRig(line.view(18), neighbour_links=(kinds.EAST,))
        self.east = StationRig(line.view(20), neighbour_links=(kinds.WEST,))
        self.drop = False  # True: what either end says is lost on the way
        self.is_up = False
        if up:
            self.link(True)

    @property
    def now(self) -> float:
        return self.west.now

    def ends(self) -> tuple[tuple[StationRig, str, StationRig, str], ...]:
        """(sender, its role for the receiver, receiver, the receiver's role for the sender)."""
        return (
            (self.west, kinds.EAST, self.east, kinds.WEST),
            (self.east, kinds.WEST, self.west, kinds.EAST),
        )

    def shuttle(self) -> None:
        """Carry what each end said to the other until both are quiet (or lose it: `drop`)."""
        for _ in range(20):
            moved = False
            for sender, role, receiver, back in self.ends():
                changes, sender.to_neighbour[role] = sender.to_neighbour[role], []
                if changes and self.is_up and not self.drop:
                    receiver.deliver(back, dict(changes))
                    moved = True
            if not moved:
                return
        raise AssertionError("the two interlockings never fell quiet")

    def link(self, up: bool) -> None:
        """The link into communication error, or back: each end then reads the other's full
        state (REQUEST_ALL, ALL_INFO), as the Type I link rebuilds it."""
        self.is_up = up
        for rig, role, _, _ in self.ends():
            rig.set_link(role, up)
            rig.to_neighbour[role].clear()  # nothing queued survives an outage
        if up:  # both full states cross on the wire: each is taken before either is read
            states = [(receiver, back, sender.ixl.full_state(role))
                      for sender, role, receiver, back in self.ends()]  # fmt: skip
            for receiver, back, state in states:
                receiver.deliver(back, state)
        self.shuttle()

    def restart(self, station: int) -> None:
        """Station `station`'s interlocking restarted (start-up locking): its neighbour sees the
        link fail and come back when the new one is up."""
        self.link(False)
        old = self.west if station == 18 else self.east
        role = kinds.EAST if station == 18 else kinds.WEST
        occupied = [tc for tc, occ in old.occupancy.items() if occ]
        rig = StationRig(
            self.line.view(station), now=self.now, occupied=occupied, startup_locking=True,
            neighbour_links=(role,),
        )  # fmt: skip
        if station == 18:
            self.west = rig
        else:
            self.east = rig

    def advance(self, seconds: float) -> None:
        """Both rigs through `seconds` of virtual time, step by step, carrying what they say."""
        end = self.now + seconds
        while self.now < end - 1e-9:
            step = min(0.5, end - self.now)
            for rig in (self.west, self.east):
                rig.advance(step)
            self.shuttle()

    def holders(self) -> list[int]:
        """The stations that hold 1820's permission."""
        return [r.view.number for r in (self.west, self.east) if r.ixl.ends[INTERVAL].holds]
