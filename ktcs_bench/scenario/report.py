"""The scenario report: speed–distance and time–distance plots (PNG) with the data behind each plot
(CSV beside it), the event log and a JSON summary.

Owns turning a finished run into files. matplotlib runs on the Agg backend (no display needed).
Speeds are drawn in km/h, the only place besides the YAML where km/h appears. Each plot's numbers
are formed once (`speed_distance_rows`, `time_distance_rows`) and both drawn and written, so the
CSV holds exactly what the plot shows:

* ``speed_distance.csv`` — one row per train and cycle: time, true front, speed (the "actual"
  line); every few cycles also the supervision limits at the max-safe front where they were
  sampled (MRSP, EBI, SBI, warning, permitted; empty between samples; `NO_LIMIT_KMH` where a
  curve sets no limit there);
* ``time_distance.csv`` — one row per train and cycle: time, front, rear;
  ``time_distance_marks.csv`` — the protection zones and station stop marks drawn behind them.
"""

from __future__ import annotations

import csv
import functools
import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, NotRequired, TypedDict

from ktcs_bench import kinds
from ktcs_bench.scenario.assertions import Outcome
from ktcs_bench.scenario.runner import RunResult, Trace
from ktcs_bench.train.units import to_kmh

NO_LIMIT_KMH = 400.0
"""A curve that limits nothing at a place (no target within reach) is drawn, and written, here."""
LIMITS = ("mrsp", "ebi", "sbi", "warning", "permitted")
"""The supervision limits the speed–distance plot draws, in the order of the curves."""
SPEED_DISTANCE_COLUMNS = (
    kinds.TRAIN,
    "t_s",
    "front_m",
    "speed_kmh",
    "safe_front_m",
    *(f"{name}_kmh" for name in LIMITS),
)
TIME_DISTANCE_COLUMNS = (kinds.TRAIN, "t_s", "front_m", "rear_m")
MARK_COLUMNS = ("kind", "name", "from_m", "to_m", "active_from_s", "active_until_s")


class AssertionSummary(TypedDict):
    place: str
    kind: str
    passed: bool
    detail: str


class TrainSummary(TypedDict):
    final_position_m: float | None
    max_speed_kmh: float
    emergency_brakes: int


class Summary(TypedDict):
    """summary.json (and `scenario run`'s JSON line): the verdict, each assertion, each train."""

    scenario: str
    file: str
    virtual_time_s: float
    passed: bool
    assertions: list[AssertionSummary]
    trains: dict[str, TrainSummary]
    events: int
    wall_time_s: NotRequired[float]
    speed_up: NotRequired[float | None]


class SpeedDistanceRow(TypedDict):
    """A row of speed_distance.csv (`SPEED_DISTANCE_COLUMNS`); the limits None when not sampled."""

    train: str
    t_s: float
    front_m: float
    speed_kmh: float
    safe_front_m: float | None
    mrsp_kmh: float | None
    ebi_kmh: float | None
    sbi_kmh: float | None
    warning_kmh: float | None
    permitted_kmh: float | None


class TimeDistanceRow(TypedDict):
    """A row of time_distance.csv (`TIME_DISTANCE_COLUMNS`)."""

    train: str
    t_s: float
    front_m: float
    rear_m: float


class MarkRow(TypedDict):
    """A row of time_distance_marks.csv (`MARK_COLUMNS`): a stop mark has no active times."""

    kind: str
    name: str
    from_m: float
    to_m: float
    active_from_s: NotRequired[float | None]
    active_until_s: NotRequired[float | None]


def summary(result: RunResult, outcomes: list[Outcome], wall_s: float | None = None) -> Summary:
    scn = result.scenario
    trains: dict[str, TrainSummary] = {}
    for tid, tr in result.traces.items():
        trains[tid] = {
            "final_position_m": round(tr.head[-1], 3) if tr.head else None,
            "max_speed_kmh": round(to_kmh(max(tr.speed)), 3) if tr.speed else 0.0,
            "emergency_brakes": sum(
                1 for e in result.events if e.train == tid and e.kind == "emergency_brake"
            ),
        }
    out: Summary = {
        "scenario": scn.name,
        "file": str(scn.path),
        "virtual_time_s": round(result.end_time, 3),
        "passed": all(o.passed for o in outcomes),
        "assertions": [
            {
                "place": o.assertion.place,
                "kind": o.assertion.kind,
                "passed": o.passed,
                "detail": o.detail,
            }
            for o in outcomes
        ],
        "trains": trains,
        "events": len(result.events),
    }
    if wall_s is not None:
        out["wall_time_s"] = round(wall_s, 3)
        out["speed_up"] = round(result.end_time / wall_s, 1) if wall_s > 0 else None
    return out


def _kmh(v: float) -> float:
    return min(to_kmh(v), NO_LIMIT_KMH) if not math.isnan(v) else NO_LIMIT_KMH


def _limit(tr: Trace, k: int | None, name: str) -> float | None:
    """Limit `name` at sample `k` of a trace, km/h; None: not sampled there."""
    values = tr.limits.get(name)
    return None if k is None or values is None else _kmh(values[k])


def speed_distance_rows(result: RunResult) -> list[SpeedDistanceRow]:
    """The speed–distance plot's numbers (`SPEED_DISTANCE_COLUMNS`), km/h; None: not sampled."""
    rows: list[SpeedDistanceRow] = []
    for tid, tr in result.traces.items():
        sampled = dict(zip(tr.limits_row, range(len(tr.limits_row)), strict=True))
        for i, (t, x, v) in enumerate(zip(tr.t, tr.head, tr.speed, strict=True)):
            k = sampled.get(i)
            limit = functools.partial(_limit, tr, k)
            rows.append(
                SpeedDistanceRow(
                    train=tid, t_s=t, front_m=x, speed_kmh=to_kmh(v),
                    safe_front_m=None if k is None else tr.limits_x[k],
                    mrsp_kmh=limit("mrsp"), ebi_kmh=limit("ebi"), sbi_kmh=limit("sbi"),
                    warning_kmh=limit("warning"), permitted_kmh=limit("permitted"),
                )
            )  # fmt: skip
    return rows


def time_distance_rows(result: RunResult) -> list[TimeDistanceRow]:
    """The time–distance plot's numbers (`TIME_DISTANCE_COLUMNS`)."""
    return [
        TimeDistanceRow(train=tid, t_s=t, front_m=head, rear_m=tail)
        for tid, tr in result.traces.items()
        for t, head, tail in zip(tr.t, tr.head, tr.tail, strict=True)
    ]


def mark_rows(result: RunResult) -> list[MarkRow]:
    """What the time–distance plot draws behind the trains (`MARK_COLUMNS`)."""
    scn = result.scenario
    rows: list[MarkRow] = [
        {
            "kind": "protection_zone",
            "name": f"zone{i + 1}",
            "from_m": z.start,
            "to_m": z.end,
            "active_from_s": z.active_from,
            "active_until_s": z.active_until,
        }
        for i, z in enumerate(scn.zones)
    ]
    rows += [
        {"kind": "stop_mark", "name": st.name, "from_m": st.stop_mark, "to_m": st.stop_mark}
        for st in scn.line.stations
    ]
    return rows


def _cell(value: object) -> object:
    """A CSV cell: numbers to 4 decimals, text as it is, nothing (None) empty."""
    if value is None or isinstance(value, str):
        return "" if value is None else value
    assert isinstance(value, int | float)
    return round(value, 4)


def _write_csv(path: Path, columns: tuple[str, ...], rows: Iterable[Mapping[str, object]]) -> None:
    """Rows (of one of the row TypedDicts above) under `columns`, in that order."""
    with path.open("w", encoding="utf-8", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, extrasaction="raise")
        w.writeheader()
        for row in rows:
            w.writerow({c: _cell(row.get(c)) for c in columns})


def plot_speed_distance(ax: Any, rows: list[SpeedDistanceRow], title: str) -> None:
    """One train's speed–distance panel from its rows (`SPEED_DISTANCE_COLUMNS`): the actual
    speed, and the supervision limits where they were sampled (none: only the actual speed)."""
    styles: list[tuple[Callable[[SpeedDistanceRow], float | None], str, str, str]] = [
        (lambda r: r["mrsp_kmh"], "MRSP", "k", "--"),
        (lambda r: r["ebi_kmh"], "EBI", "r", "-"),
        (lambda r: r["sbi_kmh"], "SBI", "orange", "-"),
        (lambda r: r["warning_kmh"], "warning", "gold", "-"),
        (lambda r: r["permitted_kmh"], "permitted", "g", "-"),
    ]
    samples = [r for r in rows if r["safe_front_m"] is not None]
    for value, label, colour, ls in styles if samples else ():
        ax.plot(
            [r["safe_front_m"] for r in samples],
            [value(r) for r in samples],
            color=colour,
            ls=ls,
            lw=1.2,
            label=label,
        )
    actual = [r["speed_kmh"] for r in rows]
    ax.plot([r["front_m"] for r in rows], actual, color="b", lw=1.6, label="actual")
    ax.set_title(title)
    ax.set_xlabel("front position (m)")
    ax.set_ylabel("speed (km/h)")
    top = max([max(actual, default=0.0)] + [m for r in samples if (m := r["mrsp_kmh"]) is not None])
    ax.set_ylim(0, top * 1.25 + 5)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)


def plot_time_distance(
    ax: Any, td: list[TimeDistanceRow], marks: list[MarkRow], title: str
) -> None:
    """Every train's front and rear over time (`TIME_DISTANCE_COLUMNS`), the marks behind them."""
    for tid in dict.fromkeys(r.get(kinds.TRAIN) for r in td):
        rows = [r for r in td if r.get(kinds.TRAIN) == tid]
        t = [r["t_s"] for r in rows]
        line = ax.plot(t, [r["front_m"] for r in rows], lw=1.4, label=f"{tid} front")
        ax.fill_between(
            t, [r["rear_m"] for r in rows], [r["front_m"] for r in rows],
            color=line[0].get_color(), alpha=0.25,
        )  # fmt: skip
    for m in marks:
        if m["kind"] == "protection_zone":
            ax.axhspan(m["from_m"], m["to_m"], color="r", alpha=0.12, label="protection zone")
        else:
            ax.axhline(m["from_m"], color="grey", lw=0.6, ls=":")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)


def write_report(
    result: RunResult, outcomes: list[Outcome], out_dir: Path, wall_s: float | None = None
) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    # speed–distance, one panel per train
    sd = speed_distance_rows(result)
    n = len(result.traces)
    fig, axes = plt.subplots(n, 1, figsize=(11, 3.6 * n), squeeze=False)
    for ax, tid in zip(axes[:, 0], result.traces, strict=True):
        rows = [r for r in sd if r.get(kinds.TRAIN) == tid]
        plot_speed_distance(ax, rows, f"{result.scenario.name}: train {tid} — speed vs distance")
    fig.tight_layout()
    paths["speed_distance"] = out_dir / "speed_distance.png"
    fig.savefig(paths["speed_distance"], dpi=110)
    plt.close(fig)
    paths["speed_distance_csv"] = out_dir / "speed_distance.csv"
    _write_csv(paths["speed_distance_csv"], SPEED_DISTANCE_COLUMNS, sd)
    # time–distance
    td = time_distance_rows(result)
    marks = mark_rows(result)
    fig, ax = plt.subplots(figsize=(11, 5))
    plot_time_distance(ax, td, marks, f"{result.scenario.name}: time–distance")
    fig.tight_layout()
    paths["time_distance"] = out_dir / "time_distance.png"
    fig.savefig(paths["time_distance"], dpi=110)
    plt.close(fig)
    paths["time_distance_csv"] = out_dir / "time_distance.csv"
    _write_csv(paths["time_distance_csv"], TIME_DISTANCE_COLUMNS, td)
    paths["time_distance_marks_csv"] = out_dir / "time_distance_marks.csv"
    _write_csv(paths["time_distance_marks_csv"], MARK_COLUMNS, marks)
    paths["events"] = out_dir / "events.log"
    with paths["events"].open("w", encoding="utf-8") as fh:
        for e in result.events:
            fh.write(f"{e.time:10.1f} s  {e.train:<6} {e.kind:<16} {e.text}\n")
    paths["summary"] = out_dir / "summary.json"
    paths["summary"].write_text(
        json.dumps(summary(result, outcomes, wall_s), indent=2, ensure_ascii=False) + "\n",
        encoding="utf-8",
    )
    return paths
