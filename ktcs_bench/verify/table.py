"""Control tables (SPEC §13): per station, one row per route as signalling engineers review it,
derived from the station data and the point geometry -- never typed by hand.

Flank protection is derived (`data.flank_routes`): for each point on the path, the signals on
the leg the route does not take whose routes would bring a train onto the point; they are held at
stop because those routes conflict with this one.
"""

from __future__ import annotations

import csv
import html
import io
from pathlib import Path

from ktcs_bench.station.model import Line, PointSetting, Route, Station, StationView
from ktcs_bench.verify.data import flank_signals

COLUMNS: tuple[str, ...] = (
    "route", "entry", "exit", "direction", "points", "track_circuits", "overlap_track_circuits",
    "overlap_points", "overlap_release", "flank_protection", "conflicting_routes", "approach",
    "approach_locking_s", "release_sections", "aspect", "speed_kmh", "interval",
)  # fmt: skip


def _points(settings: tuple[PointSetting, ...]) -> str:
    return " ".join(f"{s.point}{s.position[0].upper()}" for s in settings)


def route_row(view: StationView, route: Route) -> dict[str, str]:
    """One route's row of the control table."""
    st = view.station
    flank = flank_signals(st, route)
    overlap = bool(route.overlap_track_circuits or route.overlap_points)
    interval = view.interval_of_exit(route)
    return {
        "route": route.name,
        "entry": route.entry,
        "exit": route.exit,
        "direction": route.direction,
        "points": _points(route.points),
        "track_circuits": " ".join(route.track_circuits),
        "overlap_track_circuits": " ".join(route.overlap_track_circuits),
        "overlap_points": _points(route.overlap_points),
        "overlap_release": (
            f"with the last section, or {route.overlap_release_s:g} s after the train is in "
            "the berth"
            if overlap
            else ""
        ),
        "flank_protection": "; ".join(
            f"{p}: signal{'s' if len(sigs) > 1 else ''} {' '.join(sigs)} at stop"
            for p, sigs in flank.items()
        ),
        "conflicting_routes": " ".join(route.conflicts),
        "approach": " ".join(route.approach),
        "approach_locking_s": f"{route.approach_release_s:g}",
        "release_sections": " | ".join("+".join(sec) for sec in route.release_sections),
        "aspect": route.aspect,
        "speed_kmh": "" if route.speed_limit_kmh is None else f"{route.speed_limit_kmh:g}",
        "interval": "" if interval is None else f"departure into {interval.name}",
    }


def station_rows(line: Line, number: int) -> list[dict[str, str]]:
    view = line.view(number)
    return [route_row(view, r) for r in view.station.routes]


def station_csv(line: Line, number: int) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(station_rows(line, number))
    return buf.getvalue()


_STYLE = (
    "body{font-family:sans-serif;margin:1em}table{border-collapse:collapse;font-size:13px;"
    "margin-bottom:2em}th,td{border:1px solid #888;padding:3px 6px;vertical-align:top}"
    "th{background:#eee}td:first-child{font-weight:bold}"
)


def _station_html(line: Line, station: Station) -> str:
    head = "".join(f"<th>{html.escape(c.replace('_', ' '))}</th>" for c in COLUMNS)
    rows = []
    for row in station_rows(line, station.number):
        cells = "".join(f"<td>{html.escape(row[c])}</td>" for c in COLUMNS)
        rows.append(f"<tr>{cells}</tr>")
    return (
        f'<h2 id="st{station.number}">Station {station.number}: {html.escape(station.name)}</h2>\n'
        f"<table><tr>{head}</tr>\n" + "\n".join(rows) + "</table>\n"
    )


def index_html(line: Line) -> str:
    """Every station's table on one self-contained page (no script, no external file)."""
    stations = [line.stations[n] for n in sorted(line.stations)]
    links = " ".join(f'<a href="#st{s.number}">{s.number}</a>' for s in stations)
    body = "".join(_station_html(line, s) for s in stations)
    return (
        '<!DOCTYPE html>\n<html><head><meta charset="utf-8">'
        f"<title>Control tables: line {html.escape(line.name)}</title><style>{_STYLE}</style>"
        f"</head><body><h1>Control tables: line {html.escape(line.name)}</h1>"
        f"<p>Derived from the station data by ktcs-bench ixl table. Stations: {links}</p>\n"
        f"{body}</body></html>\n"
    )


def write_tables(line: Line, out: Path) -> list[Path]:
    """DIR/STATION.csv for every station and DIR/index.html; the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for number in sorted(line.stations):
        path = out / f"{number}.csv"
        path.write_text(station_csv(line, number), encoding="utf-8")
        written.append(path)
    index = out / "index.html"
    index.write_text(index_html(line), encoding="utf-8")
    written.append(index)
    return written
