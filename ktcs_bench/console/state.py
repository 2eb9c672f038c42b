"""What the console shows, derived from the CTC's per-station code -> state tables (pure).

`StationModel` pairs one station's data with its two Type II code charts and turns an indication
table into a JSON-ready picture (mode, link, track circuits, points, signals, routes, traffic
directions), and operator actions into control code numbers. No sockets, no clock.

A track circuit shows "locked" while a route whose track circuits (or overlap) include it reports
RSI (set and locked): the IXL->CTC chart carries route locking per route, not per track circuit,
so sections already released one by one behind a train stay shown locked until the route is.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ktcs_bench.charts import names as n
from ktcs_bench.charts.model import CodeChart
from ktcs_bench.errors import UsageError
from ktcs_bench.station.model import Line, Station, StationView

POINT_STATES = (("SNI", "normal"), ("SRI", "reverse"), ("SNR", "to_reverse"), ("SRN", "to_normal"))


@dataclass(frozen=True)
class Action:
    """One CONTROL the console sends: chart code number, value and a sentence for the log."""

    station: int
    name: str
    code: int
    value: int
    text: str


class StationModel:
    def __init__(self, view: StationView, indications: CodeChart, controls: CodeChart) -> None:
        self.view = view
        self.station: Station = view.station
        self.number = view.number
        self.indications = indications
        self.controls = controls

    # ------------------------------------------------------------------ indications -> picture

    def picture(self, state: Mapping[int, int], connected: bool, synced: bool) -> dict[str, Any]:
        """The station as the page draws it. Codes never received read as None (unknown)."""
        chart, st = self.indications, self.number

        def get(name: str) -> int | None:
            try:
                number = chart.number_of(name)
            except KeyError:
                return None
            return state.get(number)

        loc, ctc, cmr = get(n.loc(st)), get(n.ctc(st)), get(n.cmr(st))
        if ctc:
            mode = "center"
        elif cmr:
            mode = "requested"
        elif loc:
            mode = "local"
        else:
            mode = "unknown"
        routes: dict[str, dict[str, Any]] = {}
        locked_tcs: set[str] = set()
        for r in self.station.routes:
            rset = bool(get(n.rsi(st, r.name)))
            routes[r.name] = {
                "entry": r.entry,
                "exit": r.exit,
                "set": rset,
                "approach_locked": bool(get(n.ali(st, r.name))),
            }
            if rset:
                locked_tcs.update(r.all_track_circuits)
        tcs: dict[str, dict[str, Any]] = {}
        for tc in self.view.track_circuits:
            occ = get(tc.name)
            tcs[tc.name] = {
                "occupied": None if occ is None else bool(occ),
                "locked": tc.name in locked_tcs,
            }
        points: dict[str, dict[str, Any]] = {}
        for p in self.station.points:
            position = "failed" if get(n.sfi(st, p.name)) else "unknown"
            for kind, label in POINT_STATES:
                if get(f"{kind}{st}{p.name}"):
                    position = label
                    break
            points[p.name] = {
                "position": position,
                "moving": position.startswith("to_"),
                "locked": bool(get(n.sli(st, p.name))),
            }
        signals: dict[str, dict[str, Any]] = {}
        for s in self.station.signals:
            aspect: str | None = None
            for a in s.aspects:
                if get(n.asp(st, s.name, a)):
                    aspect = a
            signals[s.name] = {
                "kind": s.kind,
                "aspect": aspect,
                "held": bool(get(n.ssi(st, s.name))) if s.has_lamps else False,
                "lamp_failed": bool(get(n.lfi(st, s.name))) if s.has_lamps else False,
            }
        directions: dict[str, str | None] = {}
        for iv in self.view.intervals:
            up, down = get(n.tdu(iv.name)), get(n.tdd(iv.name))
            directions[iv.name] = "up" if up else "down" if down else None
        return {
            "station": st,
            "name": self.station.name,
            "connected": connected,
            "synced": synced,
            "mode": mode,
            "track_circuits": tcs,
            "points": points,
            "signals": signals,
            "routes": routes,
            "directions": directions,
        }

    # ------------------------------------------------------------------ actions -> controls

    def _action(self, name: str, text: str, value: int = 1) -> Action:
        try:
            code = self.controls.number_of(name)
        except KeyError:
            raise UsageError(f"station {self.number}: no control {name} in the chart") from None
        return Action(self.number, name, code, value, text)

    def route_between(self, entry: str, exit_: str) -> str:
        for r in self.station.routes:
            if r.entry == entry and r.exit == exit_:
                return r.name
        raise UsageError(f"station {self.number}: no route from signal {entry} to {exit_}")

    def set_route(self, entry: str, exit_: str) -> Action:
        route = self.route_between(entry, exit_)
        return self._action(
            n.rsc(self.number, route), f"station {self.number}: set route {entry}-{exit_}"
        )

    def cancel_route(self, entry: str, state: Mapping[int, int]) -> Action:
        """Cancel the route set from signal `entry` (the one reporting RSI)."""
        candidates = [r for r in self.station.routes if r.entry == entry]
        if not candidates:
            raise UsageError(f"station {self.number}: no route starts at signal {entry}")
        for r in candidates:
            code = self.indications.number_of(n.rsi(self.number, r.name))
            if state.get(code):
                return self._action(
                    n.rcc(self.number, r.name),
                    f"station {self.number}: cancel route {r.entry}-{r.exit}",
                )
        raise UsageError(f"station {self.number}: no route is set from signal {entry}")

    def move_point(self, point: str, position: str) -> Action:
        if point not in {p.name for p in self.station.points}:
            raise UsageError(f"station {self.number}: no point {point}")
        if position not in ("normal", "reverse"):
            raise UsageError(f"point position must be normal or reverse, not {position!r}")
        fn = n.snc if position == "normal" else n.src
        return self._action(
            fn(self.number, point), f"station {self.number}: point {point} to {position}"
        )

    def mode(self, wanted: str) -> Action:
        if wanted == "center":
            return self._action(n.cmq(self.number), f"station {self.number}: request center mode")
        if wanted == "local":
            return self._action(n.lmq(self.number), f"station {self.number}: hand back to local")
        raise UsageError(f"mode must be center or local, not {wanted!r}")


def station_models(
    line: Line, charts: Mapping[int, tuple[CodeChart, CodeChart]]
) -> dict[int, StationModel]:
    """One model per station that has charts: `charts[n] = (ixl_to_ctc, ctc_to_ixl)`."""
    return {
        number: StationModel(line.view(number), *charts[number])
        for number in sorted(line.stations)
        if number in charts
    }
