"""`chart check`: the chart files against the station data, and against what the emulators send.

Against the data: every station link has its file, and each file's header and codes (names,
types, order) are what `station_codes.stations` derives. Against the emulators: each station's
cores (the interlocking, the trackside, the wayside ATC, and the CTC's model) are built and bound
to their links as the emulator processes bind them (`binding.LinkBinding`), and every code a link
carries -- the number each end puts on the wire or reads from it -- must be the file's code of
that number; and every code a core gives or takes must be one its link carries. Between two
neighbouring IXLs (SPEC §6.6) both ends must agree: what one sends its east neighbour is what that
neighbour reads from its west, code for code, and each interlocking gives and takes exactly those.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from ktcs_bench import kinds
from ktcs_bench.atc.wayside import WaysideAtc
from ktcs_bench.binding import LinkBinding
from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.ctc.model import StationModel
from ktcs_bench.errors import ConfigError
from ktcs_bench.field.trackside import Trackside
from ktcs_bench.ixl.interlocking import Interlocking
from ktcs_bench.station.geometry import (
    GeometryError,
    LineGeometry,
    walk_route,
    walked_track_circuits,
)
from ktcs_bench.station.model import Line
from ktcs_bench.station_codes.chart import CodeChart
from ktcs_bench.station_codes.stations import (
    ChartSpec,
    build_specs,
    link_charts,
    neighbour_intervals,
    station_chart,
)


def check_charts(line: Line, chart_dir: Path, emulators: bool = True) -> list[str]:
    """Every disagreement between the chart files, the station data and the emulators."""
    problems: list[str] = []
    specs = build_specs(line)
    expected = {f"{s.stem}.yaml" for s in specs}
    for extra in sorted(p.name for p in chart_dir.glob("*.yaml") if p.name not in expected):
        problems.append(f"{chart_dir / extra}: unexpected chart (no such station link in the data)")
    files: dict[str, tuple[Path, CodeChart]] = {}
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
        files[spec.stem] = (path, chart)
        problems += _compare(path, chart, spec)
    if emulators:
        problems += _check_emulators(line, files)
        problems += _check_neighbours(line, files)
    problems += check_point_geometry(line)
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


@dataclass(frozen=True)
class _End:
    """One end of a station link as an emulator runs it: who, whether it sends or reads the link,
    the chart its binding numbers the codes by, and the codes its core gives or takes."""

    who: str  # "the IXL"
    verb: str  # "sends" | "reads"
    chart: CodeChart
    core: frozenset[str] | None  # None: the end has no core of its own to compare (the CTC)


@dataclass(frozen=True)
class _Peer:
    """The IXL's peer on one link as its emulator binds it: what it sends and reads there, and
    what its core gives and takes (None: no core of its own to compare, the CTC)."""

    who: str
    sends: CodeChart
    gives: frozenset[str] | None
    reads: CodeChart
    takes: frozenset[str] | None


def _peers(line: Line, station: int) -> dict[str, _Peer]:
    """Each of the IXL's peers (`kinds.PEER_ROLES`) at `station`, by role."""
    view = line.view(station)
    ctc, io, atc = StationModel(view), Trackside(view), WaysideAtc(line, station)

    def bound(
        who: str, role: str, state: Callable[[], dict[str, int]], takes: Iterable[str]
    ) -> _Peer:
        binding = LinkBinding(*link_charts(view, kinds.chart_name(role, False)), state)
        return _Peer(who, binding.tx, frozenset(binding.state()), binding.rx, frozenset(takes))

    return {
        kinds.CTC: _Peer("the CTC", ctc.controls, None, ctc.indications, None),
        kinds.ATC: bound("the ATC", kinds.ATC, atc.full_state, atc.input_names()),
        kinds.IO: bound("the trackside", kinds.IO, io.full_state, io.command_names()),
    }


def _ends(line: Line, station: int) -> dict[str, list[_End]]:
    """Every station link's two ends, bound as the emulator processes bind them: the IXL and
    each of its peers, one link each way."""
    view = line.view(station)
    ixl = Interlocking(view)
    out: dict[str, list[_End]] = {}
    for role, peer in _peers(line, station).items():
        outward, inward = kinds.chart_name(role, True), kinds.chart_name(role, False)
        ours = LinkBinding(*link_charts(view, outward), partial(ixl.full_state, role))
        takes = ixl.control_names() if role == kinds.CTC else ixl.input_names(role)
        out[outward] = [
            _End("the IXL", "sends", ours.tx, frozenset(ours.state())),
            _End(peer.who, "reads", peer.reads, peer.takes),
        ]
        out[inward] = [
            _End(peer.who, "sends", peer.sends, peer.gives),
            _End("the IXL", "reads", ours.rx, frozenset(takes)),
        ]
    return out


def _check_emulators(line: Line, files: dict[str, tuple[Path, CodeChart]]) -> list[str]:
    out: list[str] = []
    for st in sorted(line.stations):
        for link, ends in _ends(line, st).items():
            stem = f"st{st}_{link}"
            for end in ends:
                out += _core_against_link(stem, end)
            if stem in files:
                out += _file_against_wire(*files[stem], ends)
    return out


def _core_against_link(stem: str, end: _End) -> list[str]:
    """The codes a core gives (or takes) are the codes its link carries."""
    if end.core is None:
        return []
    carried = set(end.chart.names)
    doing = "gives" if end.verb == "sends" else "takes"
    out = [f"{stem}: {end.who} {doing} code {name!r}, which its link does not carry"
           for name in sorted(end.core - carried)]  # fmt: skip
    out += [f"{stem}: its link carries code {name!r}, which {end.who} never {doing}"
            for name in sorted(carried - end.core)]  # fmt: skip
    return out


def _file_against_wire(path: Path, file: CodeChart, ends: Iterable[_End]) -> list[str]:
    """Code k of the file is code k as each end puts it on the wire or reads it: the first
    difference, and how many more."""
    groups: dict[tuple[str, ...], list[_End]] = {}
    for end in ends:
        groups.setdefault(end.chart.names, []).append(end)
    out: list[str] = []
    for wire, who in groups.items():
        doers = " and ".join(f"{e.who} {e.verb}" for e in who)
        written = file.names
        differ = [k for k in range(max(len(wire), len(written)))
                  if k >= len(wire) or k >= len(written) or wire[k] != written[k]]  # fmt: skip
        if not differ:
            continue
        k = differ[0]
        if k >= len(written):
            text = f"{path}: code {k + 1} is missing from the file, but {doers} {wire[k]!r} as it"
        elif k >= len(wire):
            text = (
                f"{path}: code {k + 1} is {written[k]!r} in the file, but {doers} no code {k + 1}"
            )
        else:
            text = (
                f"{path}: code {k + 1} is {written[k]!r} in the file, "
                f"but {doers} {wire[k]!r} as code {k + 1}"
            )
        more = len(differ) - 1
        if more:
            text += f" (and {more} more code{'s differ' if more > 1 else ' differs'})"
        out.append(text)
    return out


def _check_neighbours(line: Line, files: dict[str, tuple[Path, CodeChart]]) -> list[str]:
    """The links between neighbouring IXLs: station A's `ixl_to_east` file is its east
    neighbour B's `west_to_ixl` file, code for code (the two ends number alike); and each
    interlocking, linked with its neighbours, gives and takes exactly what its links carry."""
    out: list[str] = []
    for st in sorted(line.stations):
        view = line.view(st)
        roles = neighbour_intervals(view)
        ixl = Interlocking(view, neighbour_links=roles)
        for role, iv in roles.items():
            outward, inward = kinds.chart_name(role, True), kinds.chart_name(role, False)
            stem = f"st{st}_{outward}"
            chart = station_chart(view, outward)
            out += _core_against_link(stem, _End("the IXL", "sends", chart,
                                                 frozenset(ixl.full_state(role))))  # fmt: skip
            out += _core_against_link(
                f"st{st}_{inward}",
                _End("the IXL", "reads", station_chart(view, inward),
                     frozenset(ixl.input_names(role))),
            )  # fmt: skip
            if role != kinds.EAST:
                continue
            other = f"st{iv.east}_{kinds.chart_name(kinds.WEST, False)}"
            if stem in files and other in files:
                (path, ours), (their_path, theirs) = files[stem], files[other]
                if ours.names != theirs.names:
                    k = next(
                        (
                            i
                            for i, (a, b) in enumerate(zip(ours.names, theirs.names, strict=False))
                            if a != b
                        ),
                        min(len(ours.names), len(theirs.names)),
                    )
                    a = ours.names[k] if k < len(ours.names) else "no code"
                    b = theirs.names[k] if k < len(theirs.names) else "no code"
                    out.append(
                        f"{path}: code {k + 1} is {a!r}, but {their_path} (the other end of "
                        f"interval {iv.name}) reads {b!r} as code {k + 1}: the ends disagree"
                    )
    return out


def check_point_geometry(line: Line) -> list[str]:
    """The points' geometry against the routes (SPEC §6.7): each point lies in its own track
    circuits, and each route run over the geometry -- its points in the positions it requires,
    from its entry signal's track -- reaches its exit signal's track and shunts exactly its own
    track circuits, and its overlap its overlap's."""
    out: list[str] = []
    geometry = LineGeometry(line)
    for st in line.stations.values():
        for i, p in enumerate(st.points):
            if not any(st.track_circuit(t).covers(p.position_m) for t in p.track_circuits):
                out.append(f"{st.file}: points[{i}].position_m: point {p.name} at "
                           f"{p.position_m:g} m lies in none of its track circuits")  # fmt: skip
        for i, r in enumerate(st.routes):
            place = f"routes[{i}]"
            try:
                walk = walk_route(st, r, place)
            except GeometryError as exc:
                out.append(f"{st.file}: {exc.place}: route {r.name}: {exc.problem}")
                continue
            for key, stretches, listed in (
                ("track_circuits", walk.route, r.track_circuits),
                ("overlap.track_circuits", walk.overlap, r.overlap_track_circuits),
            ):
                walked = walked_track_circuits(geometry, stretches)
                if walked != set(listed):
                    out.append(
                        f"{st.file}: {place}.{key}: route {r.name} lists {sorted(listed)}, its "
                        f"points as they are set run over {sorted(walked)}"
                    )
    return out
