"""The scenario report: speed–distance and time–distance plots (PNG), event log, JSON summary.

Owns turning a finished run into files. matplotlib runs on the Agg backend (no display needed).
Speeds are drawn in km/h, the only place besides the YAML where km/h appears.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ktcs_bench.scenario.assertions import Outcome
from ktcs_bench.scenario.runner import RunResult
from ktcs_bench.train.units import to_kmh


def summary(
    result: RunResult, outcomes: list[Outcome], wall_s: float | None = None
) -> dict[str, Any]:
    scn = result.scenario
    trains = {}
    for tid, tr in result.traces.items():
        trains[tid] = {
            "final_position_m": round(tr.head[-1], 3) if tr.head else None,
            "max_speed_kmh": round(to_kmh(max(tr.speed)), 3) if tr.speed else 0.0,
            "emergency_brakes": sum(
                1 for e in result.events if e.train == tid and e.kind == "emergency_brake"
            ),
        }
    out: dict[str, Any] = {
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


def write_report(
    result: RunResult, outcomes: list[Outcome], out_dir: Path, wall_s: float | None = None
) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    # speed–distance, one panel per train
    n = len(result.traces)
    fig, axes = plt.subplots(n, 1, figsize=(11, 3.6 * n), squeeze=False)
    for ax, (tid, tr) in zip(axes[:, 0], result.traces.items(), strict=True):
        lx = tr.limits_x
        styles = {
            "mrsp": ("MRSP", "k", "--"),
            "ebi": ("EBI", "r", "-"),
            "sbi": ("SBI", "orange", "-"),
            "warning": ("warning", "gold", "-"),
            "permitted": ("permitted", "g", "-"),
        }
        for key, (label, colour, ls) in styles.items():
            ys = [min(to_kmh(v), 400.0) for v in tr.limits.get(key, [])]
            if ys:
                ax.plot(lx, ys, color=colour, ls=ls, lw=1.2, label=label)
        ax.plot(tr.head, [to_kmh(v) for v in tr.speed], color="b", lw=1.6, label="actual")
        ax.set_title(f"{result.scenario.name}: train {tid} — speed vs distance")
        ax.set_xlabel("front position (m)")
        ax.set_ylabel("speed (km/h)")
        top = max(
            [to_kmh(max(tr.speed, default=0.0))] + [to_kmh(v) for v in tr.limits.get("mrsp", [0.0])]
        )
        ax.set_ylim(0, top * 1.25 + 5)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, ncol=3)
    fig.tight_layout()
    paths["speed_distance"] = out_dir / "speed_distance.png"
    fig.savefig(paths["speed_distance"], dpi=110)
    plt.close(fig)
    # time–distance
    fig, ax = plt.subplots(figsize=(11, 5))
    for tid, tr in result.traces.items():
        line = ax.plot(tr.t, tr.head, lw=1.4, label=f"{tid} front")
        ax.fill_between(tr.t, tr.tail, tr.head, color=line[0].get_color(), alpha=0.25)
    for z in result.scenario.zones:
        ax.axhspan(z.start, z.end, color="r", alpha=0.12, label="protection zone")
    for st in result.scenario.line.stations:
        ax.axhline(st.stop_mark, color="grey", lw=0.6, ls=":")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position (m)")
    ax.set_title(f"{result.scenario.name}: time–distance")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    paths["time_distance"] = out_dir / "time_distance.png"
    fig.savefig(paths["time_distance"], dpi=110)
    plt.close(fig)
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
