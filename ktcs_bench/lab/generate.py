"""A generated line on disk: `station.generate.line_files(n)` written to a folder, and the code
charts generated from the line it wrote (`ktcs-bench line generate`; format docs/line_generate.md).

Here, above both the station data and the chart files, because it needs both.
"""

from __future__ import annotations

from pathlib import Path

from ktcs_bench.chart_files.files import generate
from ktcs_bench.errors import UsageError
from ktcs_bench.station.generate import (
    CHARTS_DIR,
    LAB_FILE,
    LINE_FILE,
    STATIONS_DIR,
    TIMETABLE_FILE,
    line_files,
)
from ktcs_bench.station.loader import load_line


def owned_files(out: Path) -> list[Path]:
    """What a generated line in `out` consists of (and `--force` may replace)."""
    found = [out / name for name in (LINE_FILE, LAB_FILE, TIMETABLE_FILE)]
    found += sorted((out / STATIONS_DIR).glob("st*.yaml"))
    found += sorted((out / CHARTS_DIR).glob("st*_*.yaml"))
    return [f for f in found if f.is_file()]


def write_line(n: int, out: Path, force: bool = False) -> list[Path]:
    """Write an N-station line into `out` and generate its code charts into `out/code_charts`.

    A folder that already holds anything is refused (UsageError) unless `force`; then the files
    of an earlier generated line are removed first (nothing else is touched)."""
    files = line_files(n)
    if out.exists() and not out.is_dir():
        raise UsageError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise UsageError(f"{out} is not empty (--force replaces a generated line there)")
        for old in owned_files(out):
            old.unlink()
    written = []
    for rel, text in files.items():
        path = out / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(path)
    line = load_line(out / LINE_FILE)
    written += generate(line, out / CHARTS_DIR, LINE_FILE)
    return written
