"""Synthetic lines for the scale figures: N stations built on the reference stations' patterns.

`line_files(n)` returns the text of every file of an N-station line, keyed by its path relative
to the output folder; `lab.generate.write_line(n, out)` writes them and the code charts generated
from them (above the charts: station data imports nothing built on it):

    line.yaml              the line: plain-line track circuits, intervals, gradients, limits, ATC
    stations/stNN.yaml     one per station
    lab.yaml               CTC (with ARS), track circuits, per station an IXL, ATC and trackside
                           I/O, and a train device for each timetable train
    timetable.yaml         two trains end to end with platform stops (format: docs/line_generate.md)
    code_charts/*.yaml     `ktcs-bench chart generate` of the line

Stations are numbered 12, 14, 16, ... (two digits, as the reference's 18, 20, 22; the boundary
intervals lead to the next numbers out, 10 and 12 + 2N, which must stay two digits too: N <= 43).
Station k follows reference station 18, 20, 22 in turn -- its tracks, points, signals, routes
with their overlaps, conflicts, approach locking, release sections, aspects and speed limits,
taken from the reference file itself and moved along the line -- so a 3-station line has the
reference's shape. Track circuits are renamed to the new station (`TC1853A` of station 18 becomes
`TC1253A` of station 12). Every station owns the plain line on each side as the reference's do:
towards the west `TCss43, 45, 47` (47 is the approach to the up home signal), towards the east
`TCss61A, 63, 65` (61A is the approach to the down home signal); at the lab's edges a single
track circuit, `TCss47` and `TCss61A`.

Nothing here is random: the same N gives byte-identical files, wherever they are written (every
path inside the files is relative).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from ktcs_bench import kinds
from ktcs_bench.errors import UsageError
from ktcs_bench.station.loader import load_line
from ktcs_bench.station.model import (
    Line,
    Point,
    PointSetting,
    Route,
    Signal,
    Station,
    TrackCircuit,
)

FIRST_STATION = 12
STATION_STEP = 2
MAX_STATIONS = (98 - FIRST_STATION) // STATION_STEP  # the east boundary's number stays 2 digits
PATTERNS = (18, 20, 22)  # reference stations, taken in turn
INTERVAL_M = 4800.0  # plain line between two stations: six track circuits of 800 m
WEST_HALF = ("43", "45", "47")  # owned by the station east of the interval, up order
EAST_HALF = ("61A", "63", "65")  # owned by the station west of the interval
BOUNDARY_M = 500.0  # from a lab edge to the first/last station's home signal
STATION_AREA_MARGIN_M = 200.0  # the station's speed limit reaches this far beyond its home signals
STATION_KMH, LINE_KMH, CURVE_KMH = 80, 110, 90
CURVE_M = (1200.0, 2400.0)  # a curve in every second interval, from its west end
# gradient profiles of an interval (from its west end, ‰ rising up), after the reference's two
INTERVAL_GRADIENTS: tuple[tuple[tuple[float, float, float], ...], ...] = (
    ((0, 200, 0), (200, 1800, 8), (1800, 3600, -12), (3600, 4800, 0)),
    ((0, 200, 0), (200, 2000, 15), (2000, 3500, 2), (3500, 4600, -10), (4600, 4800, 0)),
)
STOP_SHORT_M = 20.0  # a platform stop: the train's front this far short of the starting signal
TIMETABLE_DWELL_S = 30.0
TIMETABLE_HEADWAY_S = 180.0
TIMETABLE_TRAINS = (("T1", "1"), ("T2", "2"))  # the timetable's trains and the tracks they use
INTERVAL_RUN_S = 360.0  # a train's run over an interval and its stop, with a margin (~345 s seen)
# seed 001 Table 1 (SPEC §6.5): the train both timetable trains are
TRAIN_DATA_NAME = "seed001-table1"
TRAIN_DATA = (
    ("length_m", 200),
    ("max_speed_kmh", 80),
    ("traction_kmh_per_s", 3.0),
    ("service_brake_kmh_per_s", 3.0),
    ("emergency_brake_kmh_per_s", 4.0),
)

LINE_FILE = "line.yaml"
LAB_FILE = "lab.yaml"
TIMETABLE_FILE = "timetable.yaml"
STATIONS_DIR = "stations"
CHARTS_DIR = "code_charts"


def station_numbers(n: int) -> list[int]:
    """The numbers of an N-station line, west to east; UsageError outside 1..MAX_STATIONS."""
    if not 1 <= n <= MAX_STATIONS:
        raise UsageError(
            f"a generated line has 1 to {MAX_STATIONS} stations (station numbers stay two "
            f"digits: {FIRST_STATION}, {FIRST_STATION + STATION_STEP}, ...), not {n}"
        )
    return [FIRST_STATION + STATION_STEP * k for k in range(n)]


def station_file(number: int) -> str:
    return f"{STATIONS_DIR}/st{number}.yaml"


# ---------------------------------------------------------------------------------------------
# layout


@dataclass(frozen=True)
class _Placed:
    """One station of the generated line: its number, its pattern and where it lies."""

    number: int
    pattern: Station
    shift_m: float  # new chainage = pattern chainage + shift
    west_m: float  # up home signal
    east_m: float  # down home signal

    def tc(self, name: str) -> str:
        """A track circuit of the pattern station, renamed to this station."""
        return f"TC{self.number}{name.removeprefix(f'TC{self.pattern.number}')}"

    @property
    def up_approach(self) -> str:
        return f"TC{self.number}{WEST_HALF[-1]}"

    @property
    def down_approach(self) -> str:
        return f"TC{self.number}{EAST_HALF[0]}"


def _home(st: Station, direction: str) -> Signal:
    return next(s for s in st.signals if s.kind == "home" and s.direction == direction)


def _layout(n: int, reference: Line) -> list[_Placed]:
    placed: list[_Placed] = []
    west = BOUNDARY_M
    for k, number in enumerate(station_numbers(n)):
        pattern = reference.station(PATTERNS[k % len(PATTERNS)])
        up, down = _home(pattern, "up").position_m, _home(pattern, "down").position_m
        shift = west - up
        placed.append(_Placed(number, pattern, shift, west, down + shift))
        west = down + shift + INTERVAL_M
    return placed


def _interval_name(west: int, east: int) -> str:
    return f"{west}{east}"


# ---------------------------------------------------------------------------------------------
# YAML text (flow style, as the shipped files are written)


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _q(s: str) -> str:
    return f'"{s}"'


def _names(items: Iterable[str], quote: bool = False) -> str:
    return "[" + ", ".join(_q(i) if quote else i for i in items) + "]"


def _settings(settings: Sequence[PointSetting]) -> str:
    return (
        "[" + ", ".join(f"{{point: {_q(s.point)}, position: {s.position}}}" for s in settings) + "]"
    )


def _tc_comment(tc: TrackCircuit, pattern: Station) -> str:
    points = [p.name for p in pattern.points if tc.name in p.track_circuits]
    if points:
        return ("point " if len(points) == 1 else "points ") + ", ".join(points)
    if len(tc.tracks) == 1:
        return f"track {tc.tracks[0]}" + (" (main)" if tc.tracks[0] == "1" else "")
    return "tracks " + ", ".join(tc.tracks) if tc.tracks else ""


def _geometry(pt: Point) -> str:
    """The point's geometry fields (SPEC §6.7), as its pattern station has them."""
    toe = "" if pt.toe is None else f"toe: {_q(pt.toe)}, "
    return f"facing: {pt.facing}, {toe}normal: {_q(pt.normal)}, reverse: {_q(pt.reverse)}"


def _signal_comment(s: Signal, into: dict[str, str]) -> str:
    if s.kind == "marker":
        if s.track is not None:
            return "buffer stop"
        return f"{s.direction} block limit (into {into[s.direction]})"
    if s.kind == "home":
        return f"{s.direction} home"
    return ""


def _station_text(p: _Placed, n: int, into: dict[str, str]) -> str:
    st, shift = p.pattern, p.shift_m
    out = [
        f"# Station {p.number}: generated by `ktcs-bench line generate --stations {n}` on the "
        f"pattern of reference station {st.number}.",
        "# Chainage in metres along the line; 'up' = rising chainage.",
        f"station: {p.number}",
        f"name: Station {p.number}",
        f"tracks: {_names(st.tracks, quote=True)}",
        "",
        "track_circuits:",
    ]
    for t in st.track_circuits:
        fields = (
            f"name: {p.tc(t.name)}, from_m: {_num(t.from_m + shift)}, to_m: {_num(t.to_m + shift)}"
        )
        if t.length_m != t.to_m - t.from_m:
            fields += f", length_m: {_num(t.length_m)}"
        if t.tracks:
            fields += f", tracks: {_names(t.tracks, quote=True)}"
        comment = _tc_comment(t, st)
        out.append(f"  - {{{fields}}}" + (f"  # {comment}" if comment else ""))
    out += ["", "points:"]
    for pt in st.points:
        out.append(
            f"  - {{name: {_q(pt.name)}, track_circuits: {_names(p.tc(t) for t in pt.track_circuits)}, "
            f"position_m: {_num(pt.position_m + shift)}, {_geometry(pt)}, "
            f"throw_time_s: {_num(pt.throw_time_s)}}}"
        )
    out += ["", "signals:"]
    for s in st.signals:
        fields = f"name: {_q(s.name)}, kind: {s.kind}, direction: {s.direction}, "
        fields += f"position_m: {_num(s.position_m + shift)}"
        if s.aspects:
            fields += f", aspects: {_names(s.aspects)}"
        if s.track is not None:
            fields += f", track: {_q(s.track)}"
        comment = _signal_comment(s, into)
        out.append(f"  - {{{fields}}}" + (f"  # {comment}" if comment else ""))
    out += ["", "routes:"]
    for r in st.routes:
        out += _route_text(r, p)
    return "\n".join(out) + "\n"


def _route_text(r: Route, p: _Placed) -> list[str]:
    own = {t.name for t in p.pattern.track_circuits}

    def approach(t: str) -> str:
        if t in own:
            return p.tc(t)
        return p.up_approach if r.direction == "up" else p.down_approach

    out = [
        f"  - name: {_q(r.name)}",
        f"    entry: {_q(r.entry)}",
        f"    exit: {_q(r.exit)}",
        f"    points: {_settings(r.points)}",
        f"    track_circuits: {_names(p.tc(t) for t in r.track_circuits)}",
    ]
    if r.overlap_track_circuits or r.overlap_points:
        out += [
            "    overlap:",
            f"      track_circuits: {_names(p.tc(t) for t in r.overlap_track_circuits)}",
            f"      points: {_settings(r.overlap_points)}",
        ]
    out += [
        f"    conflicts: {_names(r.conflicts, quote=True)}",
        f"    approach: {_names(approach(t) for t in r.approach)}",
        f"    approach_release_s: {_num(r.approach_release_s)}",
    ]
    if r.overlap_track_circuits:
        out.append(f"    overlap_release_s: {_num(r.overlap_release_s)}")
    sections = ", ".join(_names(p.tc(t) for t in sec) for sec in r.release_sections)
    out += [f"    release_sections: [{sections}]", f"    aspect: {r.aspect}"]
    if r.speed_limit_kmh is not None:
        out.append(f"    speed_limit_kmh: {_num(r.speed_limit_kmh)}")
    return out


def _merged(spans: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    """Adjacent spans with the same value joined."""
    out: list[tuple[float, float, float]] = []
    for lo, hi, v in spans:
        if out and out[-1][2] == v and out[-1][1] == lo:
            out[-1] = (out[-1][0], hi, v)
        else:
            out.append((lo, hi, v))
    return out


def _spans(key: str, field: str, spans: list[tuple[float, float, float]], note: str) -> list[str]:
    """A line-file table of spans along the line (adjacent equal ones joined)."""
    rows = [f"  - {{from_m: {_num(lo)}, to_m: {_num(hi)}, {field}: {_num(v)}}}"
            for lo, hi, v in _merged(spans)]  # fmt: skip
    return [f"# {key}: {note}", f"{key}:", *rows, ""]


def _line_text(placed: list[_Placed], reference: Line, n: int) -> str:
    first, last = placed[0], placed[-1]
    end_m = last.east_m + BOUNDARY_M
    tcs: list[tuple[str, float, float, int, str]] = [
        (first.up_approach, 0.0, first.west_m, first.number, "approach to the first up home")
    ]
    intervals: list[str] = [
        f'  - {{name: "{_interval_name(first.number - STATION_STEP, first.number)}", '
        f"west: {first.number - STATION_STEP}, east: {first.number}, from_m: 0, "
        f"to_m: {_num(first.west_m)}, track_circuits: [{first.up_approach}],\n"
        "     boundary: true, default_direction: up}"
    ]
    gradients: list[tuple[float, float, float]] = [(0.0, first.west_m, 0.0)]
    limits: list[tuple[float, float, float]] = [(0.0, first.west_m, STATION_KMH)]
    for k, (w, e) in enumerate(zip(placed, placed[1:], strict=False)):
        lo = w.east_m
        step = INTERVAL_M / (len(EAST_HALF) + len(WEST_HALF))
        names = [f"TC{w.number}{s}" for s in EAST_HALF] + [f"TC{e.number}{s}" for s in WEST_HALF]
        owners = [w.number] * len(EAST_HALF) + [e.number] * len(WEST_HALF)
        for i, (nm, owner) in enumerate(zip(names, owners, strict=True)):
            note = ""
            if nm == w.down_approach:
                note = f"approach to st.{w.number} down home"
            elif nm == e.up_approach:
                note = f"approach to st.{e.number} up home"
            tcs.append((nm, lo + i * step, lo + (i + 1) * step, owner, note))
        intervals.append(
            f'  - {{name: "{_interval_name(w.number, e.number)}", west: {w.number}, '
            f"east: {e.number}, from_m: {_num(lo)}, to_m: {_num(e.west_m)},\n"
            f"     track_circuits: {_names(names)}, default_direction: up}}"
        )
        gradients.append((w.west_m, w.east_m, 0.0))
        gradients += [(lo + a, lo + b, g) for a, b, g in INTERVAL_GRADIENTS[k % 2]]
        area = STATION_AREA_MARGIN_M
        limits.append((w.west_m, w.east_m + area, STATION_KMH))
        if k % 2:
            c0, c1 = CURVE_M
            limits += [(lo + area, lo + c0, LINE_KMH), (lo + c0, lo + c1, CURVE_KMH)]
            limits.append((lo + c1, e.west_m - area, LINE_KMH))
        else:
            limits.append((lo + area, e.west_m - area, LINE_KMH))
        limits.append((e.west_m - area, e.west_m, STATION_KMH))
    tcs.append(
        (last.down_approach, last.east_m, end_m, last.number, "approach to the last down home")
    )
    intervals.append(
        f'  - {{name: "{_interval_name(last.number, last.number + STATION_STEP)}", '
        f"west: {last.number}, east: {last.number + STATION_STEP}, from_m: {_num(last.east_m)}, "
        f"to_m: {_num(end_m)}, track_circuits: [{last.down_approach}],\n"
        "     boundary: true, default_direction: down}"
    )
    gradients += [(last.west_m, last.east_m, 0.0), (last.east_m, end_m, 0.0)]
    limits.append((last.west_m, end_m, STATION_KMH))
    numbers = [p.number for p in placed]
    out = [
        f"# A synthetic line of {n} station{'s' if n > 1 else ''} ({', '.join(map(str, numbers))}),"
        f" generated by `ktcs-bench line generate --stations {n}`.",
        "# Each station follows a reference station's pattern (18, 20, 22 in turn); the plain line",
        f"# between two stations is {_num(INTERVAL_M)} m, six track circuits, the west station owning"
        " the three",
        "# nearer it. Chainage in metres; 'up' = rising chainage. Format: emulators/lines/reference.yaml.",
        f"line: line{n}",
        "start_m: 0",
        f"end_m: {_num(end_m)}",
        "",
        "stations:",
        *(f"  - {{number: {p.number}, file: {station_file(p.number)}}}" for p in placed),
        "",
        "track_circuits:",
    ]
    for nm, lo, hi, owner, note in tcs:
        row = f"  - {{name: {nm}, from_m: {_num(lo)}, to_m: {_num(hi)}, station: {owner}}}"
        out.append(row + (f"  # {note}" if note else ""))
    out += ["", "intervals:", *intervals, ""]
    out += _spans("gradients", "permille", gradients, "‰, positive = rising in the up direction")
    out += _spans("speed_limits", "kmh", limits, "km/h; diverging routes carry their own limit")
    out += [
        "# Wayside ATC: speed code -> target speed, as on the reference line.",
        "atc:",
        f"  service_brake_mps2: {_num(reference.service_brake_mps2)}",
        f"  brake_build_up_s: {_num(reference.brake_build_up_s)}",
        "  codes:",
    ]
    codes = sorted(reference.speed_codes, key=lambda c: c.code)
    out += [f"    - {{code: {c.code}, kmh: {_num(c.kmh)}}}" for c in codes]
    out += [
        "",
        "# Balises/tags for the onboard position: one every spacing_m from start_m.",
        "tags:",
    ]
    out.append(f"  spacing_m: {_num(reference.tag_spacing_m)}")
    return "\n".join(out) + "\n"


def _lab_text(placed: list[_Placed], n: int) -> str:
    out = [
        f"# The lab of the generated {n}-station line (generated by `ktcs-bench line generate"
        f" --stations {n}`):",
        "# one CTC, the track-circuit emulator, per station its IXL, wayside ATC and trackside I/O,"
        " every",
        "# link through a tap, and a train device for each train of the timetable, whose routes the"
        " CTC's",
        "# automatic route setting (ARS) sets. Format: emulators/labs/reference.yaml.",
        f"lab: line{n}",
        f"description: generated line of {n} station{'s' if n > 1 else ''}, CTC, wayside ATC, "
        f"trackside I/O, track circuits and {len(TIMETABLE_TRAINS)} trains",
        f"line: {LINE_FILE}",
        f"timetable: {TIMETABLE_FILE}    # the lab's timetable: the train devices run it, ARS sets"
        " its routes",
        "ars: {}                     # the CTC's automatic route setting, on at every station",
        "",
        "type1:",
        "  profile: ktcs-type1",
        "  line_rate: 9600           # bit/s, 8N1 (10 bits a byte); null: unpaced",
        "  longest_frame_data: 132   # sizes ΔR and the ACK timeout (SPEC §3.4)",
        "type2:",
        "  profile: ktcs-type2",
        "  port: 0                   # the CTC's Type II port (0: any free port; the link map prints it)",
        "console:",
        "  port: 0                   # the CTC web console: any free port (the link map prints it)",
        "  origins: []",
        "ixl_mode: center",
        "",
        "devices:",
        "  ctc: {kind: ctc, host: 127.0.0.1}",
        "  tc: {kind: trackcircuit, host: 127.0.0.1}",
    ]
    for p in placed:
        for kind in kinds.STATION_KINDS:  # each named by its link role: ixl18, atc18, io18
            out.append(
                f"  {kinds.KINDS[kind].role}{p.number}: "
                f"{{kind: {kind}, station: {p.number}, host: 127.0.0.1}}"
            )
    first = placed[0].number
    for k, (train, track) in enumerate(TIMETABLE_TRAINS):
        out.append(
            f"  train{train}: {{kind: train, train: {train}, host: 127.0.0.1}}   # stands at "
            f"station {first} track {track}, leaves at {_num(k * TIMETABLE_HEADWAY_S)} s"
        )
    out += ["", "links:"]
    for p in placed:
        s = p.number
        for peer in kinds.IXL_PEERS:  # st18-ctc, st18-atc, st18-io: a link per peer, by role
            b = f"{peer.role}{s}" if peer.station else peer.name
            out.append(
                f"  - {{name: st{s}-{peer.role}, type: {peer.link}, a: {kinds.IXL}{s}, b: {b}, "
                "tap: true}"
            )
    for west, east in zip(placed, placed[1:], strict=False):  # the neighbouring IXLs (SPEC §6.6)
        w, e = west.number, east.number
        out.append(
            f"  - {{name: iv{w}{e}, type: {kinds.TYPE1}, a: {kinds.IXL}{w}, b: {kinds.IXL}{e}, "
            "tap: true}"
        )
    return "\n".join(out) + "\n"


def platform_stop_m(st: Station, track: str, direction: str = "up") -> float:
    """Where a train running `direction` stops at `track`: its front STOP_SHORT_M short of the
    track's starting signal."""
    sig = next(
        s
        for s in st.signals
        if s.kind == "starting" and s.direction == direction and s.track == track
    )
    return sig.position_m - STOP_SHORT_M if direction == "up" else sig.position_m + STOP_SHORT_M


TIMETABLE_HEADER = """\
# Timetable of the generated line: two trains running up (rising chainage) from the first station
# to the last, the second following the first. Format (docs/line_generate.md):
#   timetable: NAME                the timetable's name
#   line: FILE                     the line file it runs on (relative to this file)
#   train_data: {NAME: {...}}      train data by name: length_m, max_speed_kmh, and traction,
#                                  service and emergency brake rates in km/h/s (seed 001 Table 1)
#   trains: a list of
#     id: T1                       the train's name
#     train: NAME                  its train data (a key of train_data)
#     depart_s: 0                  when it leaves its first stop, s from the timetable's start
#     direction: up                the direction it runs (up = rising chainage)
#     stops: the stations in running order, each
#       {station: 12, track: "1", stop_m: 1080, dwell_s: 30}
#         track: the platform track it uses; stop_m: where its front stops (20 m short of the
#         track's starting signal); dwell_s: how long it stands there. The first stop is where
#         the train stands until depart_s; the last is its terminus (it stays there).
"""


def _timetable_text(placed: list[_Placed], n: int) -> str:
    out = [
        TIMETABLE_HEADER.rstrip("\n"),
        f"timetable: line{n}",
        f"line: {LINE_FILE}",
        "",
        "train_data:",
        f"  {TRAIN_DATA_NAME}: {{" + ", ".join(f"{k}: {_num(v)}" for k, v in TRAIN_DATA) + "}",
        "",
        "trains:",
    ]
    for k, (train, track) in enumerate(TIMETABLE_TRAINS):
        out += [
            f"  - id: {train}",
            f"    train: {TRAIN_DATA_NAME}",
            f"    depart_s: {_num(k * TIMETABLE_HEADWAY_S)}",
            "    direction: up",
            "    stops:",
        ]
        for i, p in enumerate(placed):
            stop = platform_stop_m(p.pattern, track) + p.shift_m
            dwell = TIMETABLE_DWELL_S if 0 < i < len(placed) - 1 else 0.0
            out.append(
                f"      - {{station: {p.number}, track: {_q(track)}, stop_m: {_num(stop)}, "
                f"dwell_s: {_num(dwell)}}}"
            )
    return "\n".join(out) + "\n"


def run_through_s(n: int) -> int:
    """Seconds of lab time enough for the timetable's last train to reach the last station of an
    N-station line (a `lab simulate --for` that sees both trains to their terminus)."""
    last_departs = (len(TIMETABLE_TRAINS) - 1) * TIMETABLE_HEADWAY_S
    return int(math.ceil((last_departs + (n - 1) * INTERVAL_RUN_S + 60.0) / 100.0) * 100)


# ---------------------------------------------------------------------------------------------
# the files


def line_files(n: int, reference: Line | None = None) -> dict[str, str]:
    """Every data file of an N-station line (path relative to the output folder -> text), the
    code charts aside. `reference`: the line whose stations are the patterns (default: shipped)."""
    reference = reference if reference is not None else load_line()
    placed = _layout(n, reference)
    files: dict[str, str] = {LINE_FILE: _line_text(placed, reference, n)}
    for k, p in enumerate(placed):
        west = placed[k - 1].number if k > 0 else p.number - STATION_STEP
        east = placed[k + 1].number if k + 1 < len(placed) else p.number + STATION_STEP
        into = {"up": _interval_name(p.number, east), "down": _interval_name(west, p.number)}
        files[station_file(p.number)] = _station_text(p, n, into)
    files[LAB_FILE] = _lab_text(placed, n)
    files[TIMETABLE_FILE] = _timetable_text(placed, n)
    return files
