"""In-process stations for the console's demo and tests: a real interlocking + trackside over TCP.

`RigIxl` is an `IxlApplication` (Type II) around `ixl.rig.StationRig` -- the real `Interlocking`
wired to the real `Trackside` -- run on the asyncio loop's clock: controls go to the interlocking,
a ticker walks the rig through its deadlines (point throws, timed releases) and every change of
the IXL->CTC picture is pushed to the CTC as INDICATION changes. It is an adapter for people
without the full multi-process lab, not the lab's IXL emulator.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import replace

from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.ixl.rig import StationRig
from ktcs_bench.station.model import Line, Station
from ktcs_bench.type2.ixl_client import IxlClient

TICK_S = 0.05  # how often the rig's timers are honoured


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
        self.rig = StationRig(line.view(station), mode=mode)
        self.indications = self.rig.ixl.charts["ixl_to_ctc"]  # the interlocking's own charts
        self.controls = self.rig.ixl.charts["ctc_to_ixl"]
        self.station = station
        self.client: IxlClient | None = None
        self._t0 = 0.0
        self._sent: dict[str, int] = dict(self.rig.ctc)
        self._ticker: asyncio.Task[None] | None = None

    # -- IxlApplication ------------------------------------------------------------------------
    def full_state(self) -> list[tuple[int, int]]:
        self._sent = dict(self.rig.ctc)
        return sorted((self.indications.number_of(k), v) for k, v in self.rig.ctc.items())

    def on_control(self, code: int, value: int) -> tuple[bool, int]:
        self._catch_up()
        name = self.controls.name_of(code)
        if name is None:
            return False, int(Reason.UNKNOWN_CODE)
        result = self.rig.control(name, value)
        self.push()
        return result.accepted, int(result.reason)

    # -- driving it ----------------------------------------------------------------------------
    def start(self, host: str, port: int) -> IxlClient:
        loop = asyncio.get_running_loop()
        self._t0 = loop.time() - self.rig.now
        self.client = IxlClient(self.station, host, port, self, backoff_initial=0.05)
        self.client.start()
        self._ticker = loop.create_task(self._tick())
        return self.client

    async def close(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
        if self.client is not None:
            await self.client.close()

    def occupy(self, tc: str, occupied: bool = True) -> None:
        """A train on (or off) a track circuit, as the ATC would report it."""
        self._catch_up()
        self.rig.occupy(tc, occupied)
        self.push()

    def local(self, action: str) -> None:
        """The local operator's panel: "grant" / "refuse" a center-mode request, "take" control."""
        self._catch_up()
        self.rig.take(self.rig.ixl.local(action, self.rig.now))
        self.push()

    def push(self) -> None:
        changes = [(k, v) for k, v in self.rig.ctc.items() if self._sent.get(k) != v]
        if not changes:
            return
        self._sent.update(changes)
        if self.client is not None:
            self.client.indicate((self.indications.number_of(k), v) for k, v in changes)

    def _catch_up(self) -> None:
        now = asyncio.get_running_loop().time() - self._t0
        if now > self.rig.now:
            self.rig.advance(now - self.rig.now)

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            self._catch_up()
            self.push()
