"""The line's track diagram as SVG, laid out from station and line data (no hand-drawn picture).

Owns geometry only: where each track circuit, point, signal and station label goes, with ids and
`data-*` attributes the page's script uses to colour them from the live state, and where a train
stands on the drawing (`Layout.place`: the console sends the page each train's place, the page
draws it in the diagram's `trains` layer). It knows nothing of codes, sockets or the browser.

Layout: chainage runs left to right on a piecewise-linear, non-uniform scale (plain-line track
circuits get a fixed width, station areas are stretched) so that a 13 km line with 1 km stations
fits a screen. Station track "1" (or the first track) is the main line; the other tracks get
lanes above or below it, a track that branches off another non-main track going beyond it. A track
circuit carried by several tracks (a point's track circuit) lies on its base lane, with a diagonal
to each other track's lane at the boundary where that track continues on its own.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from html import escape

from ktcs_bench.station.model import Line, Signal, Station, TrackCircuit

PLAIN_TC_PX = 64.0  # width of one plain-line track circuit
STATION_PX_PER_M = 0.42  # scale inside stations
MIN_GAP_PX = 34.0  # narrowest station segment (point track circuits are ~100 m)
LANE_PX = 34.0  # vertical distance between station tracks
MARGIN_X = 30.0
TOP_PX = 118.0  # the main line's y, below the station headers


@dataclass(frozen=True)
class Segment:
    tc: str
    station: int
    x1: float
    y1: float
    x2: float
    y2: float
    point: str | None = None  # the point whose leg this is
    leg: str | None = None  # "normal" (straight on past the point) or "reverse" (diverging)


@dataclass(frozen=True)
class TrainPlace:
    """A train on the drawing: its front's and rear's x and the y of the track it is on, px."""

    head_x: float
    tail_x: float
    y: float

    def to_json(self) -> dict[str, float]:
        return {"head_x": round(self.head_x, 1), "tail_x": round(self.tail_x, 1), "y": self.y}


@dataclass
class Layout:
    width: float
    height: float
    segments: list[Segment] = field(default_factory=list)
    svg: str = ""
    scale: Scale | None = None
    y0: float = TOP_PX
    stations: list[tuple[float, float, dict[str, float]]] = field(default_factory=list)
    """Each station's extent (m) and the y of each of its tracks."""

    def place(self, head_m: float, tail_m: float, track: str | None = None) -> TrainPlace:
        """Where a train with its front at `head_m` and rear at `tail_m` is drawn: on the lane
        of `track` in the station its front is in (the main line elsewhere, or with no track)."""
        assert self.scale is not None
        y = self.y0
        for lo, hi, lanes in self.stations:
            if track is not None and lo <= head_m <= hi and track in lanes:
                y = lanes[track]
        return TrainPlace(self.scale.x(head_m), self.scale.x(tail_m), y)


def lane_order(station: Station) -> dict[str, int]:
    """Lane of each track: 0 = main, +k below, -k above."""
    tracks = list(station.tracks)
    if not tracks:
        return {}
    main = "1" if "1" in tracks else tracks[0]
    lanes: dict[str, int] = {main: 0}
    multi = [t.tracks for t in station.track_circuits if len(t.tracks) > 1]

    def parent_of(track: str) -> str | None:
        lists = [ts for ts in multi if track in ts]
        if not lists or any(main in ts for ts in lists):
            return main
        for ts in lists:
            for other in ts:
                if other != track and other in lanes:
                    return other
        return None

    def free(start: int, step: int) -> int:
        lane = start
        while lane in lanes.values():
            lane += step
        return lane

    pending = [t for t in tracks if t != main]
    side = 1
    while pending:
        progressed = False
        for track in list(pending):
            parent = parent_of(track)
            if parent is None:
                continue
            p = lanes[parent]
            if p == 0:
                below, above = free(1, 1), free(-1, -1)
                lanes[track] = below if side > 0 else above
                side = -side
            else:
                sign = 1 if p > 0 else -1
                lanes[track] = free(p + sign, sign)
            pending.remove(track)
            progressed = True
        if not progressed:  # no branching information: alternate below/above
            track = pending.pop(0)
            lanes[track] = free(1, 1) if side > 0 else free(-1, -1)
            side = -side
    return lanes


class Scale:
    """Chainage (m) to x (px): fixed width per plain track circuit, stretched stations."""

    def __init__(self, line: Line) -> None:
        plain = line.track_circuits
        bounds = sorted({line.start_m, line.end_m} | {b for t in line.all_track_circuits()
                                                        for b in (t.from_m, t.to_m)})  # fmt: skip
        self.breaks: list[float] = bounds
        self.xs: list[float] = [MARGIN_X]
        for a, b in zip(bounds, bounds[1:], strict=False):
            mid = (a + b) / 2
            if any(t.from_m <= mid <= t.to_m for t in plain):
                width = PLAIN_TC_PX
            else:
                width = max(MIN_GAP_PX, (b - a) * STATION_PX_PER_M)
            self.xs.append(self.xs[-1] + width)
        self.width = self.xs[-1] + MARGIN_X

    def x(self, m: float) -> float:
        b, xs = self.breaks, self.xs
        if m <= b[0]:
            return xs[0]
        for i in range(1, len(b)):
            if m <= b[i]:
                f = (m - b[i - 1]) / (b[i] - b[i - 1]) if b[i] > b[i - 1] else 0.0
                return xs[i - 1] + f * (xs[i] - xs[i - 1])
        return xs[-1]


def _tracks_of(tc: TrackCircuit, station: Station | None) -> tuple[str, ...]:
    if station is None:
        return ()
    return tc.tracks or station.tracks


def _base_lane(tc: TrackCircuit, lanes: dict[str, int]) -> int:
    if not tc.tracks:
        return 0
    return min((lanes.get(t, 0) for t in tc.tracks), key=lambda v: (abs(v), v < 0))


def _f(v: float) -> str:
    return f"{v:.1f}"


def build(line: Line) -> Layout:
    """Lay the line out and render the SVG."""
    scale = Scale(line)
    lanes_of = {n: lane_order(st) for n, st in line.stations.items()}
    max_below = max([0, *(v for ls in lanes_of.values() for v in ls.values())])
    height = TOP_PX + (max_below + 1) * LANE_PX + 60
    y0 = TOP_PX

    def y(lane: int) -> float:
        return y0 + lane * LANE_PX

    layout = Layout(scale.width, height, scale=scale, y0=y0)
    for st in line.stations.values():
        if st.track_circuits:
            lo = min(t.from_m for t in st.track_circuits)
            hi = max(t.to_m for t in st.track_circuits)
            ys = {track: y(lane) for track, lane in lanes_of[st.number].items()}
            layout.stations.append((lo, hi, ys))
    segs = layout.segments
    point_of_tc: dict[str, tuple[int, str, float]] = {}
    for st in line.stations.values():
        for p in st.points:
            for tc_name in p.track_circuits:
                point_of_tc[tc_name] = (st.number, p.name, p.position_m)

    # station track circuits, with diagonals for multi-track ones
    for st in line.stations.values():
        lanes = lanes_of[st.number]
        own = list(st.track_circuits)
        for tc in own:
            base = _base_lane(tc, lanes)
            x1, x2 = scale.x(tc.from_m), scale.x(tc.to_m)
            tracks = _tracks_of(tc, st)
            pinfo = point_of_tc.get(tc.name)
            pname = pinfo[1] if pinfo else None
            px = scale.x(pinfo[2]) if pinfo else (x1 + x2) / 2
            diagonals: list[Segment] = []
            for track in tracks if len(tracks) > 1 else ():
                lane = lanes.get(track, 0)
                if lane == base:
                    continue
                for boundary in (tc.from_m, tc.to_m):
                    nxt = [
                        o for o in own
                        if o is not tc and boundary in (o.from_m, o.to_m)
                        and track in _tracks_of(o, st) and _base_lane(o, lanes) == lane
                    ]  # fmt: skip
                    if nxt:
                        bx = scale.x(boundary)
                        diagonals.append(
                            Segment(tc.name, st.number, px, y(base), bx, y(lane), pname, "reverse")
                        )
            ends = {d.x2 for d in diagonals}
            if pname is not None and len(ends) == 1:
                # split the straight track at the point: common part, then the normal leg
                b = ends.pop()
                far = x1 if abs(b - x2) < abs(b - x1) else x2
                segs.append(Segment(tc.name, st.number, far, y(base), px, y(base)))
                segs.append(Segment(tc.name, st.number, px, y(base), b, y(base), pname, "normal"))
            else:
                segs.append(Segment(tc.name, st.number, x1, y(base), x2, y(base)))
            segs.extend(diagonals)
    for tc in line.track_circuits:
        segs.append(Segment(tc.name, tc.station, scale.x(tc.from_m), y0, scale.x(tc.to_m), y0))

    parts: list[str] = [
        f'<svg xmlns="http://www.w3.org/2000/svg" id="diagram" class="diagram" '
        f'viewBox="0 0 {_f(scale.width)} {_f(height)}" width="{_f(scale.width)}" '
        f'height="{_f(height)}" data-line="{escape(line.name)}">'
    ]
    # intervals: name, traffic direction arrow and who holds (or asks for) the permission
    for iv in line.intervals:
        parts.append(_interval_svg(iv.name, scale.x(iv.from_m), scale.x(iv.to_m), y0))
    # station headers: name, mode, link
    for st in line.stations.values():
        xs = [scale.x(t.from_m) for t in st.track_circuits] + [
            scale.x(t.to_m) for t in st.track_circuits
        ]
        xa, xb = min(xs), max(xs)
        cx = (xa + xb) / 2
        parts.append(
            f'<g class="station" id="st-{st.number}" data-station="{st.number}">'
            f'<rect class="st-box" x="{_f(xa - 6)}" y="6" width="{_f(xb - xa + 12)}" height="'
            f'{_f(height - 12)}" rx="6"/>'
            f'<text class="st-name" x="{_f(cx)}" y="24">{escape(st.name)}</text>'
            f'<text class="st-mode" x="{_f(cx)}" y="40">?</text>'
            f'<text class="st-link" x="{_f(cx)}" y="55">?</text></g>'
        )
    # track circuits
    for s in segs:
        diag = f" leg-{s.leg}" if s.leg is not None else ""
        pt = f' data-point="{escape(s.point)}" data-leg="{s.leg}"' if s.point is not None else ""
        parts.append(
            f'<line class="tc{diag}" data-tc="{escape(s.tc)}" data-station="{s.station}"{pt} '
            f'x1="{_f(s.x1)}" y1="{_f(s.y1)}" x2="{_f(s.x2)}" y2="{_f(s.y2)}"/>'
        )
    # track-circuit joints and labels
    for tc in line.all_track_circuits():
        lane = _base_lane(tc, lanes_of.get(tc.station, {}))
        xa, xb = scale.x(tc.from_m), scale.x(tc.to_m)
        for xj in (xa, xb):
            parts.append(
                f'<line class="joint" x1="{_f(xj)}" y1="{_f(y(lane) - 5)}" '
                f'x2="{_f(xj)}" y2="{_f(y(lane) + 5)}"/>'
            )
        label_y = y(lane) + (-8 if lane <= 0 else 16)
        short = tc.name.removeprefix("TC")
        parts.append(
            f'<text class="tc-name" x="{_f((xa + xb) / 2)}" y="{_f(label_y)}">{escape(short)}</text>'
        )
    # points
    for st in line.stations.values():
        lanes = lanes_of[st.number]
        for p in st.points:
            tc = st.track_circuit(p.track_circuits[0])
            lane = _base_lane(tc, lanes)
            px, py = scale.x(p.position_m), y(lane)
            ly = py + (22 if lane >= 0 else -14)
            parts.append(
                f'<g class="point" id="pt-{st.number}-{escape(p.name)}" data-station="{st.number}"'
                f' data-point="{escape(p.name)}"><circle class="pt-dot" cx="{_f(px)}" '
                f'cy="{_f(py)}" r="5"/><text class="pt-label" x="{_f(px)}" y="{_f(ly)}">'
                f'{escape(p.name)}<tspan class="pt-state"></tspan></text></g>'
            )
    # signals
    for st in line.stations.values():
        lanes = lanes_of[st.number]
        for sg in st.signals:
            parts.append(_signal_svg(st, sg, scale, y(lanes.get(sg.track or "", 0))))
    parts.append('<g id="trains" class="trains"></g>')  # the page draws the trains here
    parts.append("</svg>")
    layout.svg = "".join(parts)
    return layout


def _interval_svg(name: str, xa: float, xb: float, y0: float) -> str:
    """An interval's name over an arrow along it. Both heads are drawn; the page keeps the one of
    the permission's direction (class `up` or `down` on the group) and shows a neutral mark --
    the shaft alone, dashed -- while no direction is indicated (class `none`, the default)."""
    cx, ay = (xa + xb) / 2, y0 - 30
    half = min(70.0, max(12.0, (xb - xa) / 2 - 10))
    x1, x2 = cx - half, cx + half
    e = escape(name)
    return (
        f'<g class="interval none" id="iv-{e}" data-interval="{e}" data-direction="">'
        f'<text class="iv-name" x="{_f(cx)}" y="{_f(y0 - 44)}">{e}</text>'
        f'<line class="iv-shaft" x1="{_f(x1)}" y1="{_f(ay)}" x2="{_f(x2)}" y2="{_f(ay)}"/>'
        f'<polygon class="iv-head up" points="{_f(x2 + 7)},{_f(ay)} {_f(x2)},{_f(ay - 4)} '
        f'{_f(x2)},{_f(ay + 4)}"/>'
        f'<polygon class="iv-head down" points="{_f(x1 - 7)},{_f(ay)} {_f(x1)},{_f(ay - 4)} '
        f'{_f(x1)},{_f(ay + 4)}"/>'
        f'<text class="iv-dir" x="{_f(cx)}" y="{_f(y0 - 16)}"></text></g>'
    )


def _signal_svg(st: Station, sg: Signal, scale: Scale, ty: float) -> str:
    """A signal beside its track: below for up (left to right), above for down; head faces travel."""
    up = sg.direction == "up"
    x = scale.x(sg.position_m) + (-4 if up else 4)
    if sg.kind == "shunt":
        x += -12 if up else 12
    yy = ty + (14 if up else -14)
    d = 1 if up else -1
    sid = f"sig-{st.number}-{escape(sg.name)}"
    common = (
        f'class="signal {escape(sg.kind)}" id="{sid}" data-station="{st.number}" '
        f'data-signal="{escape(sg.name)}" data-kind="{escape(sg.kind)}" '
        f'data-direction="{sg.direction}"'
    )
    label = f'<text class="sig-label" x="{_f(x - d * 10)}" y="{_f(yy + d * 16 + 4)}">'
    label += f"{escape(sg.name)}</text>"
    if sg.kind == "marker":
        return (
            f'<g {common}><rect class="hit" x="{_f(x - 9)}" y="{_f(yy - 9)}" width="18" '
            f'height="18"/><line class="marker-bar" x1="{_f(x)}" y1="{_f(yy - 7)}" x2="{_f(x)}" '
            f'y2="{_f(yy + 7)}"/>{label}</g>'
        )
    r = 4.5 if sg.kind == "shunt" else 6.0
    hx = x + d * (8 + r)
    return (
        f'<g {common}><rect class="hit" x="{_f(min(x, hx) - r - 4)}" y="{_f(yy - r - 4)}" '
        f'width="{_f(abs(hx - x) + 2 * r + 8)}" height="{_f(2 * r + 8)}"/>'
        f'<line class="sig-post" x1="{_f(x)}" y1="{_f(yy - r)}" x2="{_f(x)}" y2="{_f(yy + r)}"/>'
        f'<line class="sig-arm" x1="{_f(x)}" y1="{_f(yy)}" x2="{_f(hx - d * r)}" y2="{_f(yy)}"/>'
        f'<circle class="sig-head" cx="{_f(hx)}" cy="{_f(yy)}" r="{r}"/>{label}</g>'
    )
