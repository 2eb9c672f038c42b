"""The lab's live status, per station, as a signalling engineer reads it: mode, routes, points,
signals, occupancy and link states, in colour on a terminal."""

from __future__ import annotations

from typing import Any

GREEN, RED, YELLOW, CYAN, DIM, BOLD, RESET = (
    "\x1b[32m", "\x1b[31m", "\x1b[33m", "\x1b[36m", "\x1b[2m", "\x1b[1m", "\x1b[0m"
)  # fmt: skip
ASPECT = {"R": RED, "Y": YELLOW, "YG": YELLOW, "G": GREEN}
# a point's position as the CTC's summary reads it (ctc.model) -> its letter, as the console's
POINT = {"normal": "N", "reverse": "R", "to_normal": "→N", "to_reverse": "→R", "failed": "F"}


def _c(text: str, colour: str, on: bool) -> str:
    return f"{colour}{text}{RESET}" if on else text


def link_map_text(entries: list[dict[str, Any]], colour: bool) -> str:
    rows = [_c("link map", BOLD, colour)]
    for e in entries:
        ends = f"{e.get('a', '')} {e.get('a_end', '')}"
        if e.get("b_end"):
            ends += f"  <->  {e.get('b', '')} {e['b_end']}"
        tap = f"  tap {e['tap']}" if e.get("tap") else ""
        real = f"  external: {', '.join(e['external'])}" if e.get("external") else ""
        rows.append(f"  {e['link']:<18} {e['type']:<12} {ends}{tap}{real}")
    return "\n".join(rows)


def station_lines(status: dict[str, Any], colour: bool) -> list[str]:
    out = []
    devices = status.get("devices", {})
    for st, s in sorted(status.get("stations", {}).items(), key=lambda kv: int(kv[0])):
        ixl = next((d.get("status") or {} for d in devices.values()
                    if (d.get("status") or {}).get("kind") == "ixl"
                    and (d.get("status") or {}).get("station") == int(st)), {})  # fmt: skip
        links = {"ctc": s.get("link") == "up", **(ixl.get("links") or {})}
        link_txt = " ".join(_c(f"{k}{'●' if up else '○'}", GREEN if up else RED, colour)
                            for k, up in links.items() if k != "ctc" or True)  # fmt: skip
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
