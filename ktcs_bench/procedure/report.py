"""Reports of a procedure run: JUnit XML (one testcase per procedure: the failed expectation and
what was seen instead), JSON for machines, and one self-contained HTML page per run -- every
step with its verdict and time, a timeline of indications, signals, codes and train positions,
the trains' speed-distance plots, and each link's capture of the run attached as pcapng (data
URIs: the page needs no server and no file beside it)."""

from __future__ import annotations

import base64
import html
import io
import json
import math
import re
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypedDict

from ktcs_bench.capture import PcapngWriter
from ktcs_bench.emulator.device import Event
from ktcs_bench.evidence.coverage import COVERAGE_FILE, FORMAT, merge
from ktcs_bench.junit import JUnitCase, JUnitSuite, junit_xml, requirement_properties
from ktcs_bench.lab.invariants import ViolationJson
from ktcs_bench.procedure.coverage import procedure_coverage
from ktcs_bench.procedure.runner import ProcedureResult, StepJson, Supervised

_COLOUR = {"pass": "\x1b[32m", "fail": "\x1b[31m", "error": "\x1b[35m", "skipped": "\x1b[2m"}
_RESET = "\x1b[0m"
_OUTCOME = {"pass": "pass", "fail": "fail", "error": "error", "skipped": "skip"}
COUNTED = ("pass", "fail", "error", "skipped")


# -- text --------------------------------------------------------------------------------------------
def result_text(result: ProcedureResult, colour: bool) -> str:
    p = result.procedure

    def paint(verdict: str, text: str) -> str:
        return f"{_COLOUR.get(verdict, '')}{text}{_RESET}" if colour else text

    head = paint(result.verdict, result.verdict.upper().ljust(5))
    lines = [f"{head} {p.id}: {p.title}  ({result.duration:.1f} s, {result.mode})"]
    if result.setup_error:
        lines.append(f"      setup: {result.setup_error}")
    for s in result.steps:
        if s.verdict == "skipped":
            continue
        mark = paint(s.verdict, s.verdict.ljust(5))
        line = f"  {s.index:3d} {mark} {s.start:7.1f} s  {s.title}"
        if s.verdict != "pass":
            line += f"\n            {s.message}" + (f"; seen: {s.seen}" if s.seen else "")
        lines.append(line)
    for t, text, seen in result.broken:
        lines.append(paint("fail", f"      always: {text} broken at {t:.1f} s; seen: {seen}"))
    if result.interrupted or result.not_run:
        lines.append(f"      {result.message}")
    if result.cleared:
        lines.append(f"      cleared: {', '.join(result.cleared)}")
    return "\n".join(lines)


# -- JUnit and JSON ------------------------------------------------------------------------------------
def _details(result: ProcedureResult) -> str:
    s = result.failed_step
    if s is None or result.interrupted:
        cleared = f"\ncleared: {', '.join(result.cleared)}" if result.cleared else ""
        return result.message + cleared
    return (f"step {s.index}: {s.title}\n{s.message}\nseen instead: {s.seen or 'nothing'}"
            + (f"\nnote: {s.note}" if s.note else ""))  # fmt: skip


def junit(results: Sequence[ProcedureResult], coverage: str = "") -> bytes:
    """One testcase per procedure, its requirement ids as properties; `coverage`: the file
    name of the run's operation coverage beside the JUnit file (a suite property)."""
    cases = []
    for r in results:
        p = r.procedure
        outcome = "error" if r.interrupted else _OUTCOME.get(r.verdict, "error")
        kind = "Interrupted" if r.interrupted else "ProcedureError"
        steps = "\n".join(f"{s.index:3d} {s.verdict:7s} {s.start:8.1f} s  {s.title}"
                          + (f"  -- {s.message}" if s.message else "") for s in r.steps)  # fmt: skip
        cases.append(JUnitCase(
            p.id, f"procedure.{'.'.join(p.tags[:1]) or 'procedure'}", r.duration, outcome,
            r.message, _details(r), steps,
            "ExpectationFailed" if outcome == "fail" else kind,
            (*requirement_properties(p.verifies), ("file", str(p.path))),
        ))  # fmt: skip
    total = sum(r.duration for r in results)
    modes = sorted({r.mode for r in results})
    props = {"mode": ", ".join(modes), **({"coverage": coverage} if coverage else {})}
    suite = JUnitSuite("ktcs-bench procedures", cases, total, props)
    return junit_xml("ktcs-bench procedures", [suite])


class TimelineJson(TypedDict):
    t_s: float
    what: str
    value: str


class TrainSampleJson(TypedDict):
    t_s: float
    head_m: float
    tail_m: float
    speed_kmh: float


class BrokenJson(TypedDict):
    """An `always:` expectation broken: when first, and what was seen."""

    t_s: float
    expectation: str
    seen: str


class ProcedureJson(TypedDict):
    """One procedure's run in the JSON report: what it is, its verdict, its steps, what the lab
    did meanwhile (timeline, trains), the frames captured per link and the faults cleared."""

    id: str
    title: str
    file: str
    page: str  # its page's file name in a report folder (`page_names`); "" when not run
    verifies: list[str]
    tags: list[str]
    mode: str
    verdict: str
    message: str
    setup_error: str
    started: float
    duration_s: float
    wall_s: float
    interrupted: bool
    steps: list[StepJson]
    always: list[str]
    broken: list[BrokenJson]
    violations: list[ViolationJson]  # the lab invariants broken (`lab invariants hold`)
    logs: dict[str, list[Event]]  # the CTC's and interlockings' events over the run
    timeline: list[TimelineJson]
    trains: dict[str, list[TrainSampleJson]]
    captures: dict[str, int]  # link -> frames captured
    cleared: list[str]


def as_json(result: ProcedureResult, page: str = "") -> ProcedureJson:
    p = result.procedure
    return {
        "id": p.id, "title": p.title, "file": str(p.path), "page": "" if result.not_run else page,
        "verifies": list(p.verifies),
        "tags": list(p.tags), "mode": result.mode, "verdict": result.verdict,
        "message": result.message, "setup_error": result.setup_error,
        "started": result.started, "duration_s": round(result.duration, 3),
        "wall_s": round(result.wall_s, 3), "interrupted": bool(result.interrupted),
        "steps": [s.as_dict() for s in result.steps],
        "always": [e.text for e in p.always],
        "broken": [{"t_s": t, "expectation": x, "seen": seen} for t, x, seen in result.broken],
        "violations": [v.to_json() for v in result.violations],
        "logs": result.logs,
        "timeline": [{"t_s": t, "what": k, "value": v} for t, k, v in result.timeline],
        "trains": {tid: [{"t_s": t, "head_m": h, "tail_m": tl, "speed_kmh": v}
                         for t, h, tl, v in series] for tid, series in result.trains.items()},
        "captures": {k: len(v) for k, v in result.captures.items()},
        "cleared": result.cleared,
    }  # fmt: skip


def json_text(results: Sequence[ProcedureResult], coverage: str = "") -> str:
    """The run as JSON; `coverage`: the file of its operation coverage (written beside it)."""
    counts = {v: sum(1 for r in results if r.verdict == v) for v in COUNTED}
    pages = page_names([r.procedure.id for r in results])
    doc: dict[str, Any] = {"summary": counts, "procedures": [
        as_json(r, page) for r, page in zip(results, pages, strict=True)]}  # fmt: skip
    if coverage:
        doc["coverage"] = coverage
    return json.dumps(doc, ensure_ascii=False, indent=1)


# -- HTML --------------------------------------------------------------------------------------------
CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:1.5em;color:#222}
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 7px;
text-align:left;vertical-align:top}th{background:#f2f2f2}
.pass{color:#fff;background:#2a8a3a}.fail{color:#fff;background:#c0392b}
.error{color:#fff;background:#8e44ad}.skipped{color:#666;background:#eee}
.v{font-weight:bold;padding:1px 6px;border-radius:3px}.meta td{border:none;padding:1px 8px}
details{margin:.4em 0}code{background:#f5f5f5;padding:0 3px}
"""
ASPECT_COLOURS = {"R": "#d22", "Y": "#e8b100", "YG": "#9c3", "G": "#2a2", "unknown": "#999"}


def _e(text: object) -> str:
    return html.escape(str(text))


def _commit() -> str:
    """The checkout's commit (read from .git, no git command), or "" when not a checkout."""
    here = Path(__file__).resolve().parents[2] / ".git"
    try:
        if here.is_file():  # a worktree: "gitdir: PATH"
            here = Path(here.read_text(encoding="utf-8").split(":", 1)[1].strip())
        head = (here / "HEAD").read_text(encoding="utf-8").strip()
        if not head.startswith("ref: "):
            return head[:12]
        ref = head[5:]
        for folder in (here, Path((here / "commondir").read_text(encoding="utf-8").strip())
                       if (here / "commondir").is_file() else here):  # fmt: skip
            base = folder if folder.is_absolute() else here / folder
            if (base / ref).is_file():
                return (base / ref).read_text(encoding="utf-8").strip()[:12]
            packed = base / "packed-refs"
            if packed.is_file():
                for line in packed.read_text(encoding="utf-8").splitlines():
                    if line.endswith(f" {ref}"):
                        return line.split()[0][:12]
    except (OSError, IndexError, UnicodeDecodeError):
        pass
    return ""


def provenance() -> str:
    """What produced a report: the product's version and commit, the machine and its Python."""
    import platform

    from ktcs_bench import __version__

    commit = _commit()
    return (f"ktcs-bench {__version__}" + (f" (commit {commit})" if commit else "")
            + f" on {platform.node() or 'an unnamed machine'}, {platform.system()} "
            f"{platform.release()}, Python {platform.python_version()}")  # fmt: skip


def _file_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        return f"(not readable: {exc})"


def _requirements(p: Any) -> str:
    """Each id the procedure verifies, with the requirement's sentence from the catalogue."""
    from ktcs_bench.errors import ConfigError
    from ktcs_bench.evidence.catalogue import shipped_catalogue

    try:
        reqs = shipped_catalogue().requirements
    except ConfigError:
        reqs = {}
    items = [f"<li><code>{_e(rid)}</code> {_e(reqs[rid].text) if rid in reqs else ''}</li>"
             for rid in p.verifies]  # fmt: skip
    return f"<ul>{''.join(items)}</ul>" if items else "-"


def _png_uri(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def moved(series: Sequence[tuple[float, float, float, float]]) -> bool:
    """Whether a train's samples (t, head, tail, km/h) show it moving at all."""
    heads = [h for _t, h, _tl, _v in series]
    return bool(heads) and (max(heads) - min(heads) > 0.5 or any(v > 0 for *_, v in series))


def _plots(result: ProcedureResult) -> str:
    """A speed-distance plot of each train that moved (one that stood still is named instead:
    its plot would be empty), and every train's position over time."""
    if not result.trains:
        return "<p>No train ran in this procedure.</p>"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ktcs_bench.scenario.report import (
        SpeedDistanceRow,
        TimeDistanceRow,
        plot_speed_distance,
        plot_time_distance,
    )

    out = []
    running = {tid: series for tid, series in result.trains.items() if moved(series)}
    still = [f"{tid} (at {series[0][1]:.0f} m)" for tid, series in result.trains.items()
             if tid not in running and series]  # fmt: skip
    if running:
        n = len(running)
        fig, axes = plt.subplots(n, 1, figsize=(10, 3.2 * n), squeeze=False)
        for ax, (tid, series) in zip(axes[:, 0], running.items(), strict=True):
            sup = result.supervision.get(tid, [])
            if sup:  # a train under ATP: its curves, its code and its emergency brakes
                rows = [SpeedDistanceRow(
                    train=tid, t_s=x.t, front_m=x.head, speed_kmh=x.speed_kmh,
                    safe_front_m=x.head, mrsp_kmh=x.limits.get("mrsp"),
                    ebi_kmh=x.limits.get("ebi"), sbi_kmh=x.limits.get("sbi"),
                    warning_kmh=x.limits.get("warning"), permitted_kmh=x.limits.get("permitted"),
                ) for x in sup]  # fmt: skip
                plot_speed_distance(ax, rows, f"train {tid}: speed vs distance, as supervised")
                _codes_and_brakes(ax, sup)
            else:  # a train the procedure moves itself: no supervision, only the actual speed
                rows = [SpeedDistanceRow(train=tid, t_s=t, front_m=h, speed_kmh=v,
                                         safe_front_m=None, mrsp_kmh=None, ebi_kmh=None,
                                         sbi_kmh=None, warning_kmh=None, permitted_kmh=None)
                        for t, h, _tl, v in series]  # fmt: skip
                plot_speed_distance(ax, rows, f"train {tid}: speed vs distance")
        fig.tight_layout()
        supervised = " ".join(t for t in running if result.supervision.get(t))
        out.append(f'<img alt="speed-distance" src="{_png_uri(fig)}" '
                   f'data-trains="{_e(" ".join(running))}" '
                   f'data-supervised="{_e(supervised)}">')  # fmt: skip
        plt.close(fig)
    if still:
        out.append(f'<p class="still">Did not move, so no speed-distance plot: '
                   f"{_e(', '.join(still))}.</p>")  # fmt: skip
    td = [TimeDistanceRow(train=tid, t_s=t, front_m=h, rear_m=tl)
          for tid, series in result.trains.items() for t, h, tl, _v in series]  # fmt: skip
    fig, ax = plt.subplots(figsize=(10, 4))
    plot_time_distance(ax, td, [], "train positions over time")
    fig.tight_layout()
    out.append(f'<img alt="time-distance" src="{_png_uri(fig)}">')
    plt.close(fig)
    return "\n".join(out)


_NOTABLE = re.compile(r"refus|reject|not accepted|fail|lost|error|ARS|by ARS", re.I)


def _logs(result: ProcedureResult) -> str:
    """Each logged device's events over the run -- refusals with their reasons, ARS, faults
    first in bold -- one collapsed list a device."""
    if not result.logs:
        return "<p>No device logged anything during the run.</p>"
    out = []
    for device, events in sorted(result.logs.items()):
        notable = sum(1 for e in events if _NOTABLE.search(str(e.get("text", ""))))
        rows = "".join(
            f"<tr><td>{_e(e.get('time', ''))}</td><td>{_e(e.get('kind', ''))}</td><td>"
            + (f"<b>{_e(e.get('text', ''))}</b>" if _NOTABLE.search(str(e.get("text", "")))
               else _e(e.get("text", "")))
            + "</td></tr>" for e in events)  # fmt: skip
        out.append(f'<details class="log" data-device="{_e(device)}"><summary>{_e(device)}: '
                   f"{len(events)} events ({notable} refusals, faults or ARS)</summary><table>"
                   f"<tr><th>time</th><th>kind</th><th>text</th></tr>{rows}</table></details>")  # fmt: skip
    return "".join(out)


def _codes_and_brakes(ax: Any, sup: Sequence[Supervised]) -> None:
    """The code under the antenna as a step line, and each emergency brake a red cross."""
    coded = [x for x in sup if x.code_kmh is not None]
    if coded:
        ax.step([x.head for x in coded], [x.code_kmh for x in coded], where="post",
                color="purple", lw=1.0, ls=":", label="code")  # fmt: skip
    brakes = [x for prev, x in zip(sup, sup[1:], strict=False)
              if x.emergency_brakes > prev.emergency_brakes]  # fmt: skip
    if brakes:
        ax.plot([x.head for x in brakes], [x.speed_kmh for x in brakes], "rX", ms=9,
                label="emergency brake")  # fmt: skip
    ax.legend(loc="upper right", fontsize=8, ncol=4)


def _lane_colour(key: str, value: str) -> str:
    if key.startswith("code "):  # the code number: 0 (stop) red, the higher the greener
        try:
            code = int(value.split()[0])
        except (ValueError, IndexError):
            return "#999"
        return "#d22" if code == 0 else f"hsl({min(40 + 14 * code, 130)},70%,42%)"
    return ASPECT_COLOURS.get(value, "#999")


LABEL_CHAR_PX = 7.0  # the widest a character of the timeline's 11 px labels is taken to be


def time_ticks(end: float, most: int = 10) -> list[float]:
    """Round times from 0 to `end` (s) for an axis, at most `most` + 1 of them: a step of 1, 2
    or 5 times a power of ten."""
    raw = max(end, 1e-9) / most
    power = 10 ** math.floor(math.log10(raw))
    step = next(k * power for k in (1, 2, 5, 10) if k * power >= raw)
    return [i * step for i in range(int(end / step + 1e-9) + 1)]


def step_labels(marks: Sequence[tuple[float, int]]) -> list[tuple[float, str, int]]:
    """The steps' marks on the timeline -- (x in px, step number), in order -- as labels (x,
    text, row): steps closer than a few px share one label ("3-7"), and each label goes to the
    first row where it clears the labels already there, so no two overlap."""
    groups: list[list[tuple[float, int]]] = []
    for x, index in sorted(marks):
        if groups and x - groups[-1][0][0] < 4:
            groups[-1].append((x, index))
        else:
            groups.append([(x, index)])
    rows: list[float] = []  # where each row's last label ends
    out = []
    for group in groups:
        x = group[0][0]
        first, last = group[0][1], group[-1][1]
        text = str(first) if first == last else f"{first}-{last}"
        width = LABEL_CHAR_PX * len(text) + 3
        row = next((i for i, right in enumerate(rows) if right < x), len(rows))
        if row == len(rows):
            rows.append(0.0)
        rows[row] = x + width
        out.append((x, text, row))
    return out


def _lanes(result: ProcedureResult) -> str:
    """An SVG strip per signal (the CTC's indication) and per ATC code that changed during the
    run, each value in its colour over time, on a time axis; the steps' starts are dashed lines,
    numbered below the axis in as many rows as keep the numbers apart."""
    changes: dict[str, list[tuple[float, str]]] = {}
    for t, k, v in result.timeline:
        if (k.startswith(("ctc ", "ixl ")) and " signal " in k) or k.startswith("code "):
            changes.setdefault(k, []).append((t, v))
    moved_ = [k for k, series in changes.items() if len({v for _, v in series}) > 1]
    # each signal as the CTC showed it, then as its interlocking had it (the vital view)
    signals = sorted((k for k in moved_ if k.startswith(("ctc ", "ixl "))),
                     key=lambda k: (k.split(" ", 1)[1], k.split()[0]))  # fmt: skip
    codes = sorted((k for k in moved_ if k.startswith("code ")), key=lambda k: k.split()[1])
    shown = signals + codes or sorted(changes)[:6]
    if not shown:
        return ""
    end = max(result.duration, 1.0)
    left, width, lane = 120, 760, 16

    def at(t: float) -> float:
        return left + width * min(max(t, 0.0), end) / end

    axis = lane * len(shown) + 6  # the time axis, under the lanes
    ran = [s for s in result.steps if s.verdict != "skipped"]
    labels = step_labels([(at(s.start), s.index) for s in ran])
    rows = 1 + max((row for *_, row in labels), default=-1)
    first_row = axis + 46
    height = first_row + 14 * rows + 4
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + width + 60}" '
             f'height="{height}" font-size="11" class="timeline">']  # fmt: skip
    for i, k in enumerate(shown):
        y = i * lane + 4
        label = k.removeprefix("ctc ") if k.startswith("ctc ") else k.replace(" signal ", " ", 1)
        parts.append(f'<text x="2" y="{y + 11}">{_e(label)}</text>')
        series = changes[k]
        for j, (t, v) in enumerate(series):
            t1 = series[j + 1][0] if j + 1 < len(series) else end
            x0, x1 = at(t), at(t1)
            parts.append(f'<rect x="{x0:.1f}" y="{y}" width="{max(x1 - x0, 0.5):.1f}" '
                         f'height="{lane - 3}" fill="{_lane_colour(k, v)}"><title>{_e(k)}: '
                         f"{_e(v)} from {t:.1f} s</title></rect>")  # fmt: skip
    parts.append(f'<line x1="{left}" y1="{axis}" x2="{left + width}" y2="{axis}" '
                 f'stroke="#333"/>')  # fmt: skip
    for t in time_ticks(end):
        x = at(t)
        parts.append(f'<line x1="{x:.1f}" y1="{axis}" x2="{x:.1f}" y2="{axis + 4}" '
                     f'stroke="#333"/><text class="tick" x="{x:.1f}" y="{axis + 15}" '
                     f'text-anchor="middle">{t:g}</text>')  # fmt: skip
    parts.append(f'<text class="axis" x="{left + width / 2:.0f}" y="{axis + 30}" '
                 f'text-anchor="middle">time since the start of the procedure (s, on the '
                 f"lab's clock)</text>")  # fmt: skip
    for s in ran:  # a fault's step in red and solid: what the lab was made to suffer
        x = at(s.start)
        look = ('stroke="#c0392b" stroke-width="2" class="fault"' if s.kind == "fault"
                else 'stroke="#555" stroke-dasharray="2,2"')  # fmt: skip
        parts.append(f'<line x1="{x:.1f}" y1="0" x2="{x:.1f}" y2="{axis}" {look}><title>step '
                     f"{s.index} at {s.start:.1f} s: {_e(s.title)}</title></line>")  # fmt: skip
    if labels:
        parts.append(f'<text x="2" y="{first_row + 10}">steps</text>')
    for x, text, row in labels:
        y = first_row + 14 * row
        parts.append(f'<line x1="{x:.1f}" y1="{y}" x2="{x:.1f}" y2="{y + 11}" stroke="#555"/>'
                     f'<text class="step" x="{x + 2:.1f}" y="{y + 10}">{_e(text)}<title>step '
                     f"{_e(text)}</title></text>")  # fmt: skip
    parts.append("</svg>")
    return "".join(parts)


def _pcapng(result: ProcedureResult, link: str) -> bytes:
    buf = io.BytesIO()
    writer = PcapngWriter(buf, link=result.link_types.get(link, "type1"))
    for rec in result.captures[link]:
        writer.write(rec)
    return buf.getvalue()


def html_report(result: ProcedureResult) -> str:
    p = result.procedure
    started = datetime.fromtimestamp(result.started, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    rows = []
    for s in result.steps:
        what = _e(s.message) + (f"<br>seen: <code>{_e(s.seen)}</code>" if s.seen else "")
        note = f"<br><i>{_e(s.note)}</i>" if s.note else ""
        rows.append(f'<tr><td>{s.index}</td><td><code>{_e(s.title)}</code>{note}</td>'
                    f'<td><span class="v {s.verdict}">{s.verdict}</span></td>'
                    f"<td>{s.start:.1f} s</td><td>{s.duration:.1f} s</td><td>{what}</td></tr>")  # fmt: skip
    changes = "".join(f"<tr><td>{t:.1f}</td><td>{_e(k)}</td><td>{_e(v)}</td></tr>"
                      for t, k, v in result.timeline)  # fmt: skip
    caps = []
    for link, records in sorted(result.captures.items()):
        data = base64.b64encode(_pcapng(result, link)).decode()
        caps.append(f'<li><a download="{_e(safe_stem(p.id))}-{_e(link)}.pcapng" '
                    f'href="data:application/vnd.tcpdump.pcap;base64,{data}">{_e(link)}.pcapng</a>'
                    f" ({len(records)} records)</li>")  # fmt: skip
    setup = (f'<p class="v error">setup: {_e(result.setup_error)}</p>'
             if result.setup_error else "")  # fmt: skip
    broken = {text: (t, seen) for t, text, seen in result.broken}
    always = "".join(
        f"<tr><td><code>{_e(e.text)}</code></td><td>"
        + (f'<span class="v fail">broken</span> at {broken[e.text][0]:.1f} s; seen: '
           f"<code>{_e(broken[e.text][1])}</code>" if e.text in broken
           else '<span class="v pass">held</span>')
        + "</td></tr>" for e in p.always)  # fmt: skip
    always_html = (f"<h2>Always</h2><p>Checked at every sample, alongside the steps.</p><table>"
                   f"<tr><th>expectation</th><th>verdict</th></tr>{always}</table>"
                   if always else "")  # fmt: skip
    if result.violations:
        rows_v = "".join(f"<tr><td>{v.time:.1f} s</td><td>{v.invariant} ({_e(v.kind)})</td>"
                         f"<td>{_e(v.where)}</td><td>{_e(v.text)}</td></tr>"
                         for v in result.violations)  # fmt: skip
        always_html += ("<h2>Lab invariants broken</h2><p>Each where it was first found "
                        "(docs/system_safety.md).</p><table><tr><th>at</th><th>invariant</th>"
                        f"<th>where</th><th>what</th></tr>{rows_v}</table>")  # fmt: skip
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{_e(p.id)}: {_e(result.verdict)}</title>
<style>{CSS}</style></head><body>
<h1>{_e(p.id)}: {_e(p.title)} <span class="v {result.verdict}">{result.verdict.upper()}</span></h1>
<table class="meta">
<tr><td>verifies</td><td>{_requirements(p)}</td></tr>
<tr><td>tags</td><td>{_e(", ".join(p.tags) or "-")}</td></tr>
<tr><td>file</td><td><code>{_e(p.path)}</code></td></tr>
<tr><td>lab</td><td>{_e(p.setup.lab.name)} ({_e(result.mode)})</td></tr>
<tr><td>started</td><td>{started}; {result.duration:.1f} s on the lab's clock, {result.wall_s:.1f} s
of wall time</td></tr>
<tr><td>result</td><td>{_e(result.message or "every step passed")}</td></tr>
<tr><td>cleared</td><td>{_e(", ".join(result.cleared) or "nothing to clear")}</td></tr>
<tr><td>made by</td><td>{_e(provenance())}</td></tr>
</table>{setup}
{always_html}
<h2>Steps</h2>
<table><tr><th>#</th><th>step</th><th>verdict</th><th>at</th><th>took</th><th>what was seen</th></tr>
{"".join(rows)}</table>
<h2>Timeline</h2>
<p>The signals as the CTC showed them and, under each, as its interlocking had them
(<code>ixl ST G</code>; red R, yellow Y, yellow-green YG, green G), and the ATC's code on each
track circuit whose code changed (red: stop, greener: faster); the dashed lines are the steps, a
solid red one a fault injected. Hover for the values.</p>
{_lanes(result)}
<details><summary>Every change of indications, signals, codes and trains
({len(result.timeline)})</summary>
<table><tr><th>t (s)</th><th>what</th><th>value</th></tr>{changes}</table></details>
<h2>Trains</h2>
{_plots(result)}
<h2>Captures of the run</h2>
<ul>{"".join(caps) or "<li>none (no tapped link)</li>"}</ul>
<h2>The devices' logs</h2>
{_logs(result)}
<h2>The files run</h2>
<details><summary>the procedure, <code>{_e(p.path.name)}</code></summary>
<pre>{_e(_file_text(p.path))}</pre></details>
<details><summary>its lab, <code>{_e(p.setup.lab.file.name)}</code></summary>
<pre>{_e(_file_text(p.setup.lab.file))}</pre></details>
</body></html>
"""


_UNSAFE = re.compile(r"[^\w.-]+")


def safe_stem(text: str) -> str:
    """`text` as the stem of a file name: word characters, '.' and '-' (any other run becomes
    '_'; no path, no leading dot, at most 80 characters)."""
    return _UNSAFE.sub("_", text).strip("._-")[:80].strip("._-") or "procedure"


def page_names(ids: Sequence[str]) -> list[str]:
    """The file name of each procedure's page, from its id (`safe_stem`): never the index's,
    and never one another's -- ids that come out alike (even but for case) get -2, -3, ..."""
    taken, out = {"index.html"}, []
    for ident in ids:
        stem = safe_stem(ident)
        name, n = f"{stem}.html", 1
        while name.lower() in taken:
            n += 1
            name = f"{stem}-{n}.html"
        taken.add(name.lower())
        out.append(name)
    return out


def write_html(result: ProcedureResult, folder: Path, name: str | None = None) -> Path:
    """The procedure's page in `folder`, as `name` (default: from its id, `page_names`)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / (name or page_names([result.procedure.id])[0])
    path.write_text(html_report(result), encoding="utf-8")
    return path


def _lab_name(result: ProcedureResult) -> str:
    return result.mode.removeprefix("live ") if result.mode.startswith("live ") else (
        result.procedure.setup.lab.name)  # fmt: skip


def index_html(results: Sequence[ProcedureResult], pages: Sequence[str | None]) -> str:
    """The run's index: what came of it (counted), when it began, the mode and the labs, and
    each procedure with its verdict, linked to its page (`pages`; None: it has none)."""
    counts = {v: sum(1 for r in results if r.verdict == v) for v in COUNTED}
    words = {"pass": "passed", "fail": "failed", "error": "in error", "skipped": "not run"}
    summary = ", ".join(f'<span class="v {v if counts[v] else ""}">{counts[v]} {words[v]}</span>'
                        for v in COUNTED if counts[v] or v != "skipped")  # fmt: skip
    began = min((r.started for r in results), default=0.0)
    when = datetime.fromtimestamp(began, UTC).strftime("%Y-%m-%d %H:%M:%S UTC") if began else "-"
    modes = sorted({"live" if r.mode.startswith("live") else r.mode for r in results})
    labs = sorted({_lab_name(r) for r in results})
    lab_time = sum(r.duration for r in results)
    wall = sum(r.wall_s for r in results)
    stopped = next((f"{r.procedure.id}: {r.message}" for r in results if r.interrupted), "")
    rows = []
    for r, page in zip(results, pages, strict=True):
        name = (f'<a href="{_e(page)}">{_e(r.procedure.id)}</a>' if page
                else _e(r.procedure.id))  # fmt: skip
        rows.append(f'<tr><td><span class="v {r.verdict}">{r.verdict}</span></td><td>{name}</td>'
                    f"<td>{_e(r.procedure.title)}</td><td>{r.duration:.1f} s</td>"
                    f"<td>{_e(r.message)}</td></tr>")  # fmt: skip
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>procedures: {counts["pass"]} of {len(results)}
passed</title><style>{CSS}</style></head><body>
<h1>Procedures</h1>
<table class="meta">
<tr id="summary"><td>result</td><td>{summary} (of {len(results)})</td></tr>
<tr id="started"><td>started</td><td>{when}</td></tr>
<tr id="mode"><td>mode</td><td>{_e(", ".join(modes) or "-")}</td></tr>
<tr id="lab"><td>lab</td><td>{_e(", ".join(labs) or "-")}</td></tr>
<tr id="made-by"><td>made by</td><td>{_e(provenance())}</td></tr>
<tr id="took"><td>took</td><td>{lab_time:.1f} s on the labs' clocks, {wall:.1f} s of wall time</td></tr>
{f'<tr id="interrupted"><td>stopped</td><td>{_e(stopped)}</td></tr>' if stopped else ""}
</table>
<table><tr><th>verdict</th><th>procedure</th><th>title</th><th>took</th><th>why</th></tr>
{"".join(rows)}</table>
</body></html>
"""


def write_reports(results: Sequence[ProcedureResult], folder: Path) -> list[Path]:
    """One HTML page per procedure run (none for one not run), an index, and the JSON of the
    run -- every file in `folder` (made if need be), named by `page_names`."""
    folder.mkdir(parents=True, exist_ok=True)
    names = page_names([r.procedure.id for r in results])
    pages = [None if r.not_run else name for r, name in zip(results, names, strict=True)]
    paths = [write_html(r, folder, name) for r, name in zip(results, pages, strict=True) if name]
    index = folder / "index.html"
    index.write_text(index_html(results, pages), encoding="utf-8")
    (folder / "results.json").write_text(json_text(results, COVERAGE_FILE) + "\n",
                                         encoding="utf-8")  # fmt: skip
    write_coverage(results, folder / COVERAGE_FILE)
    return [index, *paths]


def coverage_doc(results: Sequence[ProcedureResult]) -> dict[str, Any]:
    """The operation coverage of a run: the whole run's (every procedure's added up) and, under
    `procedures`, each one's -- a procedure that never got past its setup observed nothing."""
    ran = [r for r in results if not r.not_run and not r.setup_error]
    each = {r.procedure.id: procedure_coverage(r).as_json() for r in ran}
    whole = merge(each.values()) if each else {"format": FORMAT, "observed": [], "stations": {}}
    return {**whole, "procedures": each}


def write_coverage(results: Sequence[ProcedureResult], path: Path) -> Path:
    path.write_text(json.dumps(coverage_doc(results), indent=1, sort_keys=True) + "\n",
                    encoding="utf-8")  # fmt: skip
    return path
