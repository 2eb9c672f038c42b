"""The codes each station link carries, derived from station and line data (SPEC §5).

One chart per station, link and direction: `ixl_to_ctc`, `ctc_to_ixl` (Type II), `ixl_to_atc`,
`atc_to_ixl`, `ixl_to_io`, `io_to_ixl` (Type I), and for each neighbouring IXL the station shares a
non-boundary interval with (SPEC §6.6) `ixl_to_east`/`east_to_ixl` or `ixl_to_west`/`west_to_ixl`
(Type I: per shared interval PHI, PRQ, DRL and the sender's TTC of its half; one end's
`ixl_to_east` is its east neighbour's `west_to_ixl`, code for code). Codes are collected object by object (station,
points, signals, track circuits, routes, intervals) in data order, so a code's number is stable
while the data is. `StationCodes` holds one station's charts and what each of its names means
(`parse_code`); the totalisers (TTC) are the runs of plain-line track circuits a station owns in
each adjacent interval.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

from ktcs_bench import kinds
from ktcs_bench.station.model import Interval, Line, StationView
from ktcs_bench.station_codes.chart import Code, CodeChart
from ktcs_bench.station_codes.names import CodeName
from ktcs_bench.station_codes.names import Function as F

# (link, protocol, direction): the links of a station, each of the IXL's peers each way
# (`kinds.charts`), and the file stem suffix of each chart
LINKS: tuple[tuple[str, str, str], ...] = kinds.charts()

NEIGHBOUR_LINKS: tuple[tuple[str, str, str], ...] = tuple(
    (kinds.chart_name(role, outward), kinds.TYPE1, f"IXL->{role.upper()}" if outward else
     f"{role.upper()}->IXL")
    for role in kinds.NEIGHBOUR_ROLES
    for outward in (True, False)
)  # fmt: skip
"""The links to the neighbouring IXLs, each way: a station has those of the neighbours it has
(`neighbour_intervals`)."""

# the chart's status column: what state 1 (and 0) of each function means
ONE_ZERO: dict[str, str] = {
    F.LOC: "1 local mode",
    F.CTC: "1 center mode",
    F.CMR: "1 center mode requested, awaiting the local operator",
    F.CMQ: "1 request center mode",
    F.LMQ: "1 hand back to local mode",
    F.SNI: "1 point detected normal",
    F.SRN: "1 point moving reverse -> normal",
    F.SRI: "1 point detected reverse",
    F.SNR: "1 point moving normal -> reverse",
    F.SLI: "1 point locked by a route",
    F.SFI: "1 point failed (no detection)",
    F.SNC: "1 move point to normal",
    F.SRC: "1 move point to reverse",
    F.PNC: "1 normal demanded",
    F.PRC: "1 reverse demanded",
    F.ASP: "1 aspect shown",
    F.SSI: "1 held at stop by the CTC",
    F.LFI: "1 lamp failure",
    F.SSC: "1 hold at stop, 0 release",
    F.SGP: "1 proceed, 0 stop",
    F.SGC: "1 light this aspect",
    F.LPS: "1 lamp lit and proved",
    F.RSI: "1 route set and locked",
    F.ALI: "1 approach locked, timed release running",
    F.RSC: "1 set route",
    F.RCC: "1 cancel route",
    F.RLI: "1 route set and locked, train not yet past the entry signal",
    F.TDU: "1 traffic direction up",
    F.TDD: "1 traffic direction down",
    F.TC: "1 occupied, 0 clear",
    F.TTC: "1 occupied, 0 clear",
    F.IZC: "1 TTC occupied, 0 TTC clear",
    F.PHI: "1 holds the interval's traffic permission",
    F.PRQ: "1 asks for the interval's traffic permission",
    F.DRL: "1 a departure route into the interval is locked",
    F.DRC: "1 ask the neighbour for the interval's traffic permission",
}


def reverse(link: str) -> str:
    """The link the other way: "ixl_to_atc" -> "atc_to_ixl"."""
    sender, _, receiver = link.partition("_to_")
    return f"{receiver}_to_{sender}"


@dataclass(frozen=True, slots=True)
class Totaliser:
    """A TTC code: the track circuits a station owns in one interval, occupied if any is."""

    name: str
    interval: str
    track_circuits: tuple[str, ...]


def _ttc(view: StationView, interval: str, half: tuple[str, ...]) -> CodeName:
    return CodeName(F.TTC, view.number, interval, track_circuits=half)


def totalisers(view: StationView) -> tuple[Totaliser, ...]:
    """One per interval the station owns track circuits of, in interval order."""
    out = []
    for iv in view.intervals:
        half = view.owned_half(iv)
        if half:
            out.append(Totaliser(_ttc(view, iv.name, half).text, iv.name, half))
    return tuple(out)


@dataclass(frozen=True)
class ChartSpec:
    """A chart as the station data gives it."""

    stem: str  # file stem: st18_ixl_to_ctc
    protocol: str
    direction: str
    station: int
    names: tuple[CodeName, ...]

    @property
    def name(self) -> str:
        return self.stem.replace("_", "-")

    @property
    def codes(self) -> tuple[tuple[str, str], ...]:
        """(name, type) per code, in number order."""
        return tuple((c.text, str(c.function)) for c in self.names)

    def to_chart(self) -> CodeChart:
        codes = tuple(
            Code(i + 1, c.text, str(c.function), ONE_ZERO.get(c.function, ""))
            for i, c in enumerate(self.names)
        )
        return CodeChart(self.name, self.protocol, self.direction, codes, self.station)


def _tcs(v: StationView) -> list[CodeName]:
    return [CodeName(F.TC, t.station, t.name) for t in v.track_circuits]


def _ixl_to_ctc(v: StationView) -> list[CodeName]:
    st, station = v.number, v.station
    out = [CodeName(F.LOC, st), CodeName(F.CTC, st), CodeName(F.CMR, st)]
    for p in station.points:
        out += [CodeName(f, st, p.name) for f in (F.SNI, F.SRN, F.SRI, F.SNR, F.SLI, F.SFI)]
    for s in station.lamp_signals:
        out += [CodeName(F.ASP, st, s.name, a) for a in s.aspects]
        out += [CodeName(F.SSI, st, s.name), CodeName(F.LFI, st, s.name)]
    out += _tcs(v)
    for r in station.routes:
        out += [CodeName(F.RSI, st, r.name), CodeName(F.ALI, st, r.name)]
    for iv in v.intervals:
        out += [CodeName(F.TDU, None, iv.name), CodeName(F.TDD, None, iv.name)]
    for iv in v.intervals:  # after every older code: their numbers stay
        out += [CodeName(F.PHI, None, iv.name), CodeName(F.PRQ, None, iv.name)]
    return out


def _ctc_to_ixl(v: StationView) -> list[CodeName]:
    st, station = v.number, v.station
    out = [CodeName(F.CMQ, st), CodeName(F.LMQ, st)]
    for p in station.points:
        out += [CodeName(F.SNC, st, p.name), CodeName(F.SRC, st, p.name)]
    out += [CodeName(F.SSC, st, s.name) for s in station.lamp_signals]
    for r in station.routes:
        out += [CodeName(F.RSC, st, r.name), CodeName(F.RCC, st, r.name)]
    out += [CodeName(F.DRC, None, iv.name) for iv in v.intervals if not iv.boundary]
    return out


def neighbour_intervals(view: StationView) -> dict[str, Interval]:
    """The station's neighbour link roles (`kinds.NEIGHBOUR_ROLES`) and the interval each link
    carries: `east` for the non-boundary interval it is the west end of, `west` for the other.
    A boundary interval (a lab edge) has no IXL at its far end."""
    out: dict[str, Interval] = {}
    for iv in view.intervals:
        if iv.boundary:
            continue
        out[kinds.EAST if iv.west == view.number else kinds.WEST] = iv
    return out


def _to_neighbour(v: StationView, role: str) -> list[CodeName]:
    """What this IXL tells its neighbour `role` of their shared interval (SPEC §6.6)."""
    iv = neighbour_intervals(v)[role]
    out = [CodeName(f, None, iv.name) for f in (F.PHI, F.PRQ, F.DRL)]
    half = v.owned_half(iv)
    if half:
        out.append(_ttc(v, iv.name, half))
    return out


def _from_neighbour(v: StationView, role: str) -> list[CodeName]:
    """What the neighbour `role` tells this IXL: its own `_to_neighbour` the other way."""
    iv = neighbour_intervals(v)[role]
    other = iv.east if role == kinds.EAST else iv.west
    return _to_neighbour(v.line.view(other), kinds.WEST if role == kinds.EAST else kinds.EAST)


def _ixl_to_atc(v: StationView) -> list[CodeName]:
    st, station = v.number, v.station
    out = [CodeName(F.RLI, st, r.name) for r in station.routes]
    for p in station.points:
        out += [CodeName(F.SNI, st, p.name), CodeName(F.SRI, st, p.name)]
    out += [CodeName(F.SGP, st, s.name) for s in station.lamp_signals]
    for iv in v.intervals:
        out += [CodeName(F.TDU, None, iv.name), CodeName(F.TDD, None, iv.name)]
    return out


def _atc_to_ixl(v: StationView) -> list[CodeName]:
    out = _tcs(v)
    for iv in v.intervals:
        half = v.owned_half(iv)
        if half:
            out.append(_ttc(v, iv.name, half))
    out += [CodeName(F.IZC, None, iv.name) for iv in v.intervals]
    return out


def _ixl_to_io(v: StationView) -> list[CodeName]:
    st, station = v.number, v.station
    out: list[CodeName] = []
    for p in station.points:
        out += [CodeName(F.PNC, st, p.name), CodeName(F.PRC, st, p.name)]
    for s in station.lamp_signals:
        out += [CodeName(F.SGC, st, s.name, a) for a in s.aspects]
    return out


def _io_to_ixl(v: StationView) -> list[CodeName]:
    st, station = v.number, v.station
    out: list[CodeName] = []
    for p in station.points:
        out += [CodeName(f, st, p.name) for f in (F.SNI, F.SRN, F.SRI, F.SNR)]
    for s in station.lamp_signals:
        out += [CodeName(F.LPS, st, s.name, a) for a in s.aspects]
        out.append(CodeName(F.LFI, st, s.name))
    out += _tcs(v)
    return out


_BUILDERS: dict[str, Callable[[StationView], list[CodeName]]] = {
    "ixl_to_ctc": _ixl_to_ctc,
    "ctc_to_ixl": _ctc_to_ixl,
    "ixl_to_atc": _ixl_to_atc,
    "atc_to_ixl": _atc_to_ixl,
    "ixl_to_io": _ixl_to_io,
    "io_to_ixl": _io_to_ixl,
}
for _role in kinds.NEIGHBOUR_ROLES:
    _BUILDERS[kinds.chart_name(_role, True)] = partial(_to_neighbour, role=_role)
    _BUILDERS[kinds.chart_name(_role, False)] = partial(_from_neighbour, role=_role)


def station_links(view: StationView) -> tuple[tuple[str, str, str], ...]:
    """(link, protocol, direction) of every chart station `view` has: its peers' (`LINKS`) and
    those of the neighbouring IXLs it has (`neighbour_intervals`)."""
    roles = neighbour_intervals(view)
    mine = tuple(x for x in NEIGHBOUR_LINKS if x[0].removeprefix("ixl_to_").removesuffix(
        "_to_ixl") in roles)  # fmt: skip
    return LINKS + mine


def chart_spec(view: StationView, link: str) -> ChartSpec:
    """One station link's chart as the data gives it (`link` is e.g. "ixl_to_ctc")."""
    links = station_links(view)
    try:
        protocol, direction = next((p, d) for k, p, d in links if k == link)
    except StopIteration:
        raise ValueError(f"unknown link {link!r} ({', '.join(k for k, _, _ in links)})") from None
    names = tuple(_BUILDERS[link](view))
    return ChartSpec(f"st{view.number}_{link}", protocol, direction, view.number, names)


def station_chart(view: StationView, link: str) -> CodeChart:
    """The chart of one station's link, straight from the data."""
    return chart_spec(view, link).to_chart()


def link_charts(view: StationView, link: str) -> tuple[CodeChart, CodeChart]:
    """What a station device that sends `link` (e.g. "ixl_to_atc") sends, and what it reads back
    ("atc_to_ixl")."""
    return station_chart(view, link), station_chart(view, reverse(link))


def build_specs(line: Line) -> list[ChartSpec]:
    """Every chart of the line: station by station, link by link."""
    return [
        chart_spec(line.view(st), link)
        for st in sorted(line.stations)
        for link, _, _ in station_links(line.view(st))
    ]


class StationCodes:
    """One station's codes: which names each of its links carries, and what each name means."""

    def __init__(self, view: StationView) -> None:
        self.view = view
        self.number = view.number
        self.specs = {link: chart_spec(view, link) for link, _, _ in station_links(view)}
        self._meaning = {c.text: c for spec in self.specs.values() for c in spec.names}
        self.totalisers = totalisers(view)

    def names(self, link: str) -> tuple[str, ...]:
        """The names link `link` carries, in chart order."""
        return tuple(c.text for c in self.specs[link].names)

    def chart(self, link: str) -> CodeChart:
        return self.specs[link].to_chart()

    def parse_code(self, name: str) -> CodeName | None:
        """What `name` means at this station: function, station, object, aspect; None when no
        link of the station carries such a code."""
        return self._meaning.get(name)
