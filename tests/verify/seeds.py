"""Defects seeded into copies of the station data (the shipped files stay as they are)."""

from __future__ import annotations

import dataclasses
from typing import Any

from ktcs_bench.station import load_line
from ktcs_bench.station.model import Line, Route


def with_route(line: Line, station: int, route: str, **changes: Any) -> Line:
    """A copy of `line` whose route `route` of station `station` has `changes`."""
    st = line.station(station)
    routes = tuple(dataclasses.replace(r, **changes) if r.name == route else r for r in st.routes)
    return with_routes(line, station, routes)


def with_routes(line: Line, station: int, routes: tuple[Route, ...]) -> Line:
    st = line.station(station)
    # the lookup tables are rebuilt, never shared with the loaded (cached) station
    copy = dataclasses.replace(st, routes=routes, _tc={}, _pt={}, _sg={}, _rt={})
    return dataclasses.replace(line, stations={**line.stations, station: copy})


def without_conflict(line: Line, station: int, a: str, b: str) -> Line:
    """Routes a and b no longer list each other as conflicting."""
    st = line.station(station)
    routes = []
    for r in st.routes:
        drop = {a: b, b: a}.get(r.name)
        routes.append(r if drop is None else dataclasses.replace(
            r, conflicts=tuple(c for c in r.conflicts if c != drop)))  # fmt: skip
    return with_routes(line, station, tuple(routes))


def reference() -> Line:
    return load_line()
