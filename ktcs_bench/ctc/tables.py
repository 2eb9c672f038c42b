"""What the CTC knows of each station: its indication table and the link it comes by (pure).

`IndicationTables` is the CTC application the Type II server feeds (`transport.ctc_server.
CtcApplication`): link up/down, full states and change indications, per station. It keeps code
numbers and states only; `ctc.model` reads them as the operator's picture.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field


@dataclass
class IndicationTable:
    """One station as the CTC knows it: code number -> state, and the link's standing."""

    station: int
    state: dict[int, int] = field(default_factory=dict)
    connected: bool = False
    synced: bool = False  # a full state arrived on the current connection
    peer: str | None = None
    connections: int = 0  # accepted connections so far
    full_states: int = 0  # full-state dumps received so far
    version: int = 0  # counts every change of the table or the link (a reader may cache on it)

    @property
    def known(self) -> bool:
        """The table holds: the link is up and has brought a full state since it came up."""
        return self.connected and self.synced


class IndicationTables:
    """The CTC's indication tables, one per configured station (a station admitted beyond them
    gets one when its link comes up)."""

    def __init__(self, stations: Iterable[int]) -> None:
        self.stations: dict[int, IndicationTable] = {
            st: IndicationTable(st) for st in sorted(stations)
        }

    def link_up(self, station: int, peer: str) -> None:
        table = self.stations.setdefault(station, IndicationTable(station))
        table.connected = True
        table.synced = False
        table.peer = peer
        table.connections += 1
        table.version += 1

    def link_down(self, station: int) -> None:
        table = self.stations.get(station)
        if table is not None:
            table.connected = False
            table.synced = False
            table.version += 1

    def full_state(self, station: int, items: Sequence[tuple[int, int]]) -> None:
        table = self.stations.get(station)
        if table is not None:
            table.state = dict(items)
            table.synced = True
            table.full_states += 1
            table.version += 1

    def indications(self, station: int, items: Sequence[tuple[int, int]]) -> None:
        table = self.stations.get(station)
        if table is not None and items:
            table.state.update(items)
            table.version += 1
