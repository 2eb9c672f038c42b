"""The lab's live status, per station, as a signalling engineer reads it: mode, routes, points,
signals, occupancy and link states, then each train -- what it is doing, where, how fast, and the
platform stops it made -- in colour on a terminal."""

from __future__ import annotations

from typing import Any, Required, TypedDict

from ktcs_bench import kinds

GREEN, RED, YELLOW, CYAN, DIM, BOLD, RESET = (
    "\x1b[32m", "\x1b[31m", "\x1b[33m", "\x1b[36m", "\x1b[2m", "\x1b[1m", "\x1b[0m"
)  # fmt: skip
ASPECT = {"R": RED, "Y": YELLOW, "YG": YELLOW, "G": GREEN}
# a point's position as the CTC's summary reads it (ctc.model) -> its letter, as the console's
POINT = {"normal": "N", "reverse": "R", "to_normal": "→N", "to_reverse": "→R", "failed": "F"}


def _c(text: str, colour: str, on: bool) -> str:
    return f"{colour}{text}{RESET}" if on else text


class LinkEntry(TypedDict, total=False):
    """One row of a lab's link map (`{"cmd": "map"}`): a link, its ends and tap, or a device's
    listening port or console (no `a`, `b`)."""

    link: Required[str]
    type: Required[str]
    a: str
    b: str
    a_end: str
    b_end: str
    tap: str
    capture: str
    external: list[str]
    host: str  # a lab spread over hosts (lab.multihost): the host that runs it


def link_map_text(entries: list[LinkEntry], colour: bool) -> str:
    rows = [_c("link map", BOLD, colour)]
    for e in entries:
        ends = f"{e.get('a', '')} {e.get('a_end', '')}"
        if e.get("b_end"):
            ends += f"  <->  {e.get('b', '')} {e['b_end']}"
        tap = f"  tap {e['tap']}" if e.get("tap") else ""
        real = f"  external: {', '.join(e['external'])}" if e.get("external") else ""
        host = f"  on {e['host']}" if e.get("host") else ""
        rows.append(f"  {e['link']:<18} {e['type']:<12} {ends}{tap}{real}{host}")
    return "\n".join(rows)


TRAIN_STATE = {"running": GREEN, "stopping": YELLOW, "dwelling": CYAN, "held": RED}


def train_lines(status: dict[str, Any], colour: bool) -> list[str]:
    """One line per train process: state, front, speed, next stop, and its arrivals (station,
    stop error in m, time s)."""
    out = []
    for d in status.get("devices", {}).values():
        t = d.get("status") or {}
        if t.get("kind") != kinds.TRAIN:
            continue
        state = str(t.get("state") or "?")
        stops = " ".join(f"{a['station']}:{a['error_m']:+.2f}m@{a['time_s']:.0f}s"
                         for a in t.get("arrivals", []))  # fmt: skip
        nxt = f"next {t['next_stop']}" if t.get("next_stop") else "no stop left"
        out.append(f"{_c('train ' + str(t.get(kinds.TRAIN)), BOLD, colour)} "
                   f"{_c(state, TRAIN_STATE.get(state, ''), colour):<10} front "
                   f"{float(t.get('head', 0.0)):8.1f} m {float(t.get('speed_kmh', 0.0)):5.1f} km/h  "
                   f"{nxt}   {'stops ' + stops if stops else ''}".rstrip())  # fmt: skip
    return out


def station_lines(status: dict[str, Any], colour: bool) -> list[str]:
    out = []
    devices = status.get("devices", {})
    for st, s in sorted(status.get("stations", {}).items(), key=lambda kv: int(kv[0])):
        ixl = next((d.get("status") or {} for d in devices.values()
                    if (d.get("status") or {}).get("kind") == kinds.IXL
                    and (d.get("status") or {}).get("station") == int(st)), {})  # fmt: skip
        links = {kinds.CTC: s.get("link") == "up", **(ixl.get("links") or {})}
        link_txt = " ".join(_c(f"{k}{'●' if up else '○'}", GREEN if up else RED, colour)
                            for k, up in links.items() if k != kinds.CTC or True)  # fmt: skip
        mode = s.get("mode", "?")
        mode_txt = _c(mode, CYAN if mode == "center" else YELLOW, colour)
        none = "-" if s.get("known", True) else "unknown"  # the CTC does not know them now
        routes = ", ".join(s.get("routes", [])) or none
        points = " ".join(f"{p}:{POINT.get(pos.split(' ')[0], '?')}{'L' if 'locked' in pos else ''}"
                          for p, pos in s.get("points", {}).items())  # fmt: skip
        signals = " ".join(
            _c(f"{n}:{a}", ASPECT.get(a, ""), colour) for n, a in s.get("signals", {}).items()
        )
        occ = " ".join(s.get("occupied", [])) or none
        out.append(f"{_c(f'st{st}', BOLD, colour)} {mode_txt:<8} links {link_txt}")
        out.append(f"    routes {routes}   points {points}")
        out.append(f"    signals {signals}")
        out.append(f"    occupied {occ}")
    out += train_lines(status, colour)
    for name, d in devices.items():
        if d.get("external"):  # a real device: alive while its link is up
            up = bool(d.get("alive"))
            state = _c("link up" if up else "link down", GREEN if up else RED, colour)
            out.append(f"{_c(name, BOLD, colour)} external at {d['external']}: {state}")
        if d.get("crashed") is not None:
            out.append(
                _c(
                    f"!! {name} crashed (exit {d['crashed']}): `ktcs-bench lab restart {name}`",
                    RED,
                    colour,
                )
            )
    return out
