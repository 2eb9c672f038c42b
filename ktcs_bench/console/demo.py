"""In-process stations for the console's demo and tests: a real interlocking + trackside over TCP.

`RigIxl` serves `ixl.rig.StationRig` -- the real `Interlocking` wired to the real `Trackside` --
over Type II, run on the asyncio loop's clock: its binding (`binding.ControlLink`, the IXL
emulator's own) is the Type II application, controls go to the interlocking by name, the
wall-clock driver (`timed.aio.LoopTimer`) wakes the rig at its deadlines (point throws, timed
releases) and no more often, and every change the interlocking gives the CTC is pushed as
INDICATION changes. It is an adapter for people without
the full multi-process lab, not the lab's IXL emulator.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace

from ktcs_bench.binding import ControlLink
from ktcs_bench.ixl.interlocking import IxlEvent
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.model import Line, Station
from ktcs_bench.station_codes.stations import link_charts
from ktcs_bench.timed.aio import LoopTimer
from ktcs_bench.transport.ixl_client import IxlClient


def with_throw_time(line: Line, seconds: float) -> Line:
    """The same line with every point machine throwing in `seconds` (demos, tests)."""
    stations = {}
    for number, st in line.stations.items():
        stations[number] = Station(
            number=st.number,
            name=st.name,
            file=st.file,
            tracks=st.tracks,
            track_circuits=st.track_circuits,
            points=tuple(replace(p, throw_time_s=seconds) for p in st.points),
            signals=st.signals,
            routes=st.routes,
        )
    return replace(line, stations=stations)


class RigIxl:
    """One station's interlocking + trackside, reachable over Type II once `start()`ed."""

    def __init__(self, line: Line, station: int, *, mode: Mode = Mode.CENTER) -> None:
        view = line.view(station)
        self.rig = StationRig(view, mode=mode)
        self.link = ControlLink(
            *link_charts(view, "ixl_to_ctc"), lambda: self.rig.ctc, self._control,
            int(Reason.UNKNOWN_CODE),
        )  # fmt: skip
        self.rig.on_ctc = self._indicate
        self.station = station
        self.client: IxlClient | None = None
        self.timer: LoopTimer[list[IxlEvent]] | None = None

    # -- the application the Type II client serves ---------------------------------------------
    def full_state(self) -> list[tuple[int, int]]:
        return self.link.full_state()

    def on_control(self, code: int, value: int) -> tuple[bool, int] | None:
        self._catch_up()
        answer = self.link.on_control(code, value)
        self._poke()
        return answer

    def _control(self, name: str, value: int) -> tuple[bool, int]:
        result = self.rig.control(name, value)
        return result.accepted, int(result.reason)

    def _indicate(self, changes: list[tuple[str, int]]) -> None:
        items = self.link.send(changes)
        if items and self.client is not None:
            self.client.indicate(items)

    # -- driving it ----------------------------------------------------------------------------
    def start(self, host: str, port: int) -> IxlClient:
        origin = asyncio.get_running_loop().time() - self.rig.now
        self.timer = LoopTimer(self.rig, lambda now, events: None, origin=origin)
        self.timer.poke()
        self.client = IxlClient(self.station, host, port, self, backoff_initial=0.05)
        self.client.start()
        return self.client

    async def close(self) -> None:
        if self.timer is not None:
            self.timer.cancel()
        if self.client is not None:
            await self.client.close()

    def occupy(self, tc: str, occupied: bool = True) -> None:
        """A train on (or off) a track circuit, as the ATC would report it."""
        self._catch_up()
        self.rig.occupy(tc, occupied)
        self._poke()

    def local(self, action: str) -> None:
        """The local operator's panel: "grant" / "refuse" a center-mode request, "take" control."""
        self._catch_up()
        self.rig.take(self.rig.ixl.local(action, self.rig.now))
        self._poke()

    def _catch_up(self) -> None:
        """Bring the rig to the wall clock before an input (its timer keeps it there after)."""
        if self.timer is not None:
            self.rig.handle_timer(self.timer.now())

    def _poke(self) -> None:
        """An input may have moved the rig's deadline (a point now throwing): re-arm its timer."""
        if self.timer is not None:
            self.timer.poke()
