"""Build the code charts from station and line data, write them as YAML, and check them.

One chart per station, link and direction (SPEC §5): `stNN_ixl_to_ctc`, `stNN_ctc_to_ixl`
(Type II), `stNN_ixl_to_atc`, `stNN_atc_to_ixl`, `stNN_ixl_to_io`, `stNN_io_to_ixl` (Type I).
Codes are collected object by object (station, points, signals, track circuits, routes, intervals)
in data order, so a code's number is stable while the data is. `check_charts` compares the files
with what the data gives, and with the codes the emulators actually speak.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ktcs_bench.charts import names as n
from ktcs_bench.charts.model import Code, CodeChart, load_chart
from ktcs_bench.errors import ConfigError
from ktcs_bench.station.model import Line, StationView

# (file stem suffix, protocol, direction)
LINKS: tuple[tuple[str, str, str], ...] = (
    ("ixl_to_ctc", "type2", "IXL->CTC"),
    ("ctc_to_ixl", "type2", "CTC->IXL"),
    ("ixl_to_atc", "type1", "IXL->ATC"),
    ("atc_to_ixl", "type1", "ATC->IXL"),
    ("ixl_to_io", "type1", "IXL->IO"),
    ("io_to_ixl", "type1", "IO->IXL"),
)

ONE_ZERO = {
    "LOC": "1 local mode",
    "CTC": "1 center mode",
    "CMR": "1 center mode requested, awaiting the local operator",
    "CMQ": "1 request center mode",
    "LMQ": "1 hand back to local mode",
    "SNI": "1 point detected normal",
    "SRN": "1 point moving reverse -> normal",
    "SRI": "1 point detected reverse",
    "SNR": "1 point moving normal -> reverse",
    "SLI": "1 point locked by a route",
    "SFI": "1 point failed (no detection)",
    "SNC": "1 move point to normal",
    "SRC": "1 move point to reverse",
    "PNC": "1 normal demanded",
    "PRC": "1 reverse demanded",
    "ASP": "1 aspect shown",
    "SSI": "1 held at stop by the CTC",
    "LFI": "1 lamp failure",
    "SSC": "1 hold at stop, 0 release",
    "SGP": "1 proceed, 0 stop",
    "SGC": "1 light this aspect",
    "LPS": "1 lamp lit and proved",
    "RSI": "1 route set and locked",
    "ALI": "1 approach locked, timed release running",
    "RSC": "1 set route",
    "RCC": "1 cancel route",
    "RLI": "1 route set and locked, train not yet past the entry signal",
    "TDU": "1 traffic direction up",
    "TDD": "1 traffic direction down",
    "TC": "1 occupied, 0 clear",
    "TTC": "1 occupied, 0 clear",
    "IZC": "1 TTC occupied, 0 TTC clear",
}


@dataclass(frozen=True)
class ChartSpec:
    """A chart as the data gives it, before it is written."""

    stem: str
    protocol: str
    direction: str
    station: int
    codes: tuple[tuple[str, str], ...]  # (name, type)

    @property
    def name(self) -> str:
        return self.stem.replace("_", "-")

    def to_chart(self) -> CodeChart:
        codes = tuple(
            Code(i + 1, nm, ty, ONE_ZERO.get(ty, "")) for i, (nm, ty) in enumerate(self.codes)
        )
        return CodeChart(self.name, self.protocol, self.direction, codes, self.station)


def _ixl_to_ctc(v: StationView) -> list[tuple[str, str]]:
    st = v.number
    out = [(n.loc(st), "LOC"), (n.ctc(st), "CTC"), (n.cmr(st), "CMR")]
    for p in v.station.points:
        for fn, ty in ((n.sni, "SNI"), (n.srn, "SRN"), (n.sri, "SRI"), (n.snr, "SNR")):
            out.append((fn(st, p.name), ty))
        out += [(n.sli(st, p.name), "SLI"), (n.sfi(st, p.name), "SFI")]
    for s in v.station.lamp_signals:
        out += [(n.asp(st, s.name, a), "ASP") for a in s.aspects]
        out += [(n.ssi(st, s.name), "SSI"), (n.lfi(st, s.name), "LFI")]
    out += [(t.name, "TC") for t in v.track_circuits]
    for r in v.station.routes:
        out += [(n.rsi(st, r.name), "RSI"), (n.ali(st, r.name), "ALI")]
    for iv in v.intervals:
        out += [(n.tdu(iv.name), "TDU"), (n.tdd(iv.name), "TDD")]
    return out


def _ctc_to_ixl(v: StationView) -> list[tuple[str, str]]:
    st = v.number
    out = [(n.cmq(st), "CMQ"), (n.lmq(st), "LMQ")]
    for p in v.station.points:
        out += [(n.snc(st, p.name), "SNC"), (n.src(st, p.name), "SRC")]
    out += [(n.ssc(st, s.name), "SSC") for s in v.station.lamp_signals]
    for r in v.station.routes:
        out += [(n.rsc(st, r.name), "RSC"), (n.rcc(st, r.name), "RCC")]
    return out


def _ixl_to_atc(v: StationView) -> list[tuple[str, str]]:
    st = v.number
    out = [(n.rli(st, r.name), "RLI") for r in v.station.routes]
    for p in v.station.points:
        out += [(n.sni(st, p.name), "SNI"), (n.sri(st, p.name), "SRI")]
    out += [(n.sgp(st, s.name), "SGP") for s in v.station.lamp_signals]
    for iv in v.intervals:
        out += [(n.tdu(iv.name), "TDU"), (n.tdd(iv.name), "TDD")]
    return out


def totalisers(v: StationView) -> list[tuple[str, tuple[str, ...]]]:
    """(TTC name, its track circuits): one per interval half the station owns."""
    out = []
    for iv in v.intervals:
        half = v.owned_half(iv)
        if half:
            out.append((n.ttc(half[0], half[-1]), half))
    return out


def _atc_to_ixl(v: StationView) -> list[tuple[str, str]]:
    out = [(t.name, "TC") for t in v.track_circuits]
    out += [(name, "TTC") for name, _ in totalisers(v)]
    out += [(n.izc(iv.name), "IZC") for iv in v.intervals]
    return out


def _ixl_to_io(v: StationView) -> list[tuple[str, str]]:
    st = v.number
    out: list[tuple[str, str]] = []
    for p in v.station.points:
        out += [(n.pnc(st, p.name), "PNC"), (n.prc(st, p.name), "PRC")]
    for s in v.station.lamp_signals:
        out += [(n.sgc(st, s.name, a), "SGC") for a in s.aspects]
    return out


def _io_to_ixl(v: StationView) -> list[tuple[str, str]]:
    st = v.number
    out: list[tuple[str, str]] = []
    for p in v.station.points:
        for fn, ty in ((n.sni, "SNI"), (n.srn, "SRN"), (n.sri, "SRI"), (n.snr, "SNR")):
            out.append((fn(st, p.name), ty))
    for s in v.station.lamp_signals:
        out += [(n.lps(st, s.name, a), "LPS") for a in s.aspects]
        out.append((n.lfi(st, s.name), "LFI"))
    out += [(t.name, "TC") for t in v.track_circuits]
    return out


_BUILDERS: dict[str, Callable[[StationView], list[tuple[str, str]]]] = {
    "ixl_to_ctc": _ixl_to_ctc,
    "ctc_to_ixl": _ctc_to_ixl,
    "ixl_to_atc": _ixl_to_atc,
    "atc_to_ixl": _atc_to_ixl,
    "ixl_to_io": _ixl_to_io,
    "io_to_ixl": _io_to_ixl,
}


def station_chart(view: StationView, link: str) -> CodeChart:
    """The chart of one station's link (`link` is e.g. "ixl_to_ctc"), straight from the data."""
    return _spec(view, link).to_chart()


def _spec(view: StationView, link: str) -> ChartSpec:
    protocol, direction = next((p, d) for k, p, d in LINKS if k == link)
    return ChartSpec(
        f"st{view.number}_{link}", protocol, direction, view.number, tuple(_BUILDERS[link](view))
    )


def build_specs(line: Line) -> list[ChartSpec]:
    return [_spec(line.view(st), link) for st in sorted(line.stations) for link, _, _ in LINKS]


def render(spec: ChartSpec, source: str) -> str:
    """The YAML text of one chart: Table 2's columns Name, Type, Sequence, Status."""
    lines = [
        f"# Code chart {spec.name}: generated by `ktcs-bench chart generate` from {source}.",
        "# Do not edit: change the station data and regenerate. Code number = sequence.",
        f"chart: {spec.name}",
        f"protocol: {spec.protocol}",
        f"direction: {spec.direction}",
        f"station: {spec.station}",
        "codes:",
    ]
    for i, (nm, ty) in enumerate(spec.codes):
        status = ONE_ZERO.get(ty, "")
        lines.append(f'  - {{name: {nm}, type: {ty}, sequence: {i + 1}, status: "{status}"}}')
    return "\n".join(lines) + "\n"


def generate(
    line: Line, out_dir: Path, source: str = "emulators/lines/reference.yaml"
) -> list[Path]:
    """Write every chart of the line into `out_dir`; returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for spec in build_specs(line):
        path = out_dir / f"{spec.stem}.yaml"
        path.write_text(render(spec, source), encoding="utf-8")
        written.append(path)
    return written


def check_charts(line: Line, chart_dir: Path, emulators: bool = True) -> list[str]:
    """Every disagreement between the chart files, the station data and the emulators."""
    problems: list[str] = []
    specs = build_specs(line)
    expected = {f"{s.stem}.yaml" for s in specs}
    for extra in sorted(p.name for p in chart_dir.glob("*.yaml") if p.name not in expected):
        problems.append(f"{chart_dir / extra}: unexpected chart (no such station link in the data)")
    for spec in specs:
        path = chart_dir / f"{spec.stem}.yaml"
        if not path.exists():
            problems.append(f"{path}: missing chart (run `ktcs-bench chart generate`)")
            continue
        try:
            chart = load_chart(path)
        except ConfigError as exc:
            problems.append(str(exc))
            continue
        problems += _compare(path, chart, spec)
    if emulators:
        problems += _check_emulators(line)
    return problems


def _compare(path: Path, chart: CodeChart, spec: ChartSpec) -> list[str]:
    out: list[str] = []
    for key, have, want in (
        ("chart", chart.name, spec.name),
        ("protocol", chart.protocol, spec.protocol),
        ("direction", chart.direction, spec.direction),
        ("station", chart.station, spec.station),
    ):
        if have != want:
            out.append(f"{path}: {key}: is {have!r}, station data gives {want!r}")
    want_names = [nm for nm, _ in spec.codes]
    want_set = set(want_names)
    have_names = [c.name for c in chart.codes]
    for c in chart.codes:
        if c.name not in want_set:
            out.append(
                f"{path}: codes[{c.number - 1}].name: unknown code {c.name!r} "
                f"(no such object or code in the station data)"
            )
    for missing in [nm for nm in want_names if nm not in set(have_names)]:
        out.append(f"{path}: codes: missing code {missing!r} that the station data gives")
    if not out:
        for c, (nm, ty) in zip(chart.codes, spec.codes, strict=True):
            if c.name != nm:
                out.append(
                    f"{path}: codes[{c.number - 1}].name: code {c.number} is {c.name!r}, "
                    f"station data gives {nm!r} (order differs: regenerate)"
                )
                break
            if c.type != ty:
                out.append(f"{path}: codes[{c.number - 1}].type: is {c.type!r}, expected {ty!r}")
    return out


def _check_emulators(line: Line) -> list[str]:
    """The codes each emulator reads and writes must be exactly its chart's codes."""
    from ktcs_bench.atc.wayside import WaysideAtc
    from ktcs_bench.field.trackside import Trackside
    from ktcs_bench.ixl.interlocking import Interlocking

    out: list[str] = []
    for st in sorted(line.stations):
        view = line.view(st)
        ixl = Interlocking(view)
        io = Trackside(view)
        atc = WaysideAtc(line, st)
        speaks = {
            "ixl_to_ctc": set(ixl.full_state("ctc")),
            "ixl_to_atc": set(ixl.full_state("atc")),
            "ixl_to_io": set(ixl.full_state("io")),
            "ctc_to_ixl": set(ixl.control_names()),
            "io_to_ixl": set(io.full_state()),
            "atc_to_ixl": set(atc.full_state()),
        }
        reads = {
            "ixl_to_io": set(io.command_names()),
            "io_to_ixl": set(ixl.input_names("io")),
            "atc_to_ixl": set(ixl.input_names("atc")),
            "ixl_to_atc": set(atc.input_names()),
        }
        for link, names in list(speaks.items()) + list(reads.items()):
            chart = {c.name for c in station_chart(view, link).codes}
            who = "emulators"
            for extra in sorted(names - chart):
                out.append(f"st{st}_{link}: {who} use code {extra!r} which the chart lacks")
            for missing in sorted(chart - names):
                out.append(f"st{st}_{link}: chart code {missing!r} is not handled by the {who}")
    return out
