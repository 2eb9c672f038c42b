"""The shipped procedures under pytest (SPEC §12, `procedure.pytest_plugin`): the suite's wall
time serial and spread over two pytest-xdist workers (`-n 2`), each worker with its own labs.
The goal is at most 0.6x the serial time on a 2-core machine. Prints both and their ratio.

    .venv/bin/python benchmarks/procedures_pytest.py [FOLDER]

The development machine is a shared 2-core VM: the ratio is the figure, not the seconds, and a
loaded machine pushes it towards 1. Without pytest-xdist installed it says so and times only the
serial run.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

from ktcs_bench.datafiles import data_dir

PLUGIN = "ktcs_bench.procedure.pytest_plugin"


def timed(folder: Path, *extra: str) -> tuple[float, str]:
    """Wall seconds of one pytest run of `folder` and its output; a run that does not pass
    stops the bench."""
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", PLUGIN, "-p",
                           "no:cacheprovider", *extra, str(folder)],
                          capture_output=True, text=True)  # fmt: skip
    took = time.monotonic() - t0
    if done.returncode != 0:
        sys.exit(f"pytest {' '.join(extra)} failed:\n{done.stdout[-3000:]}{done.stderr[-2000:]}")
    return took, done.stdout


def longest(output: str, n: int = 3) -> list[str]:
    """The `n` longest items of a run with `--durations` (what bounds two workers)."""
    return [line.strip() for line in output.splitlines() if " call " in line][:n]


def main() -> None:
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else data_dir("emulators") / "procedures"
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    serial, output = timed(folder, "--durations=3")
    print(f"serial: {serial:.1f} s; the longest: {'; '.join(longest(output))}")
    if importlib.util.find_spec("xdist") is None:
        print("-n 2: pytest-xdist is not installed (pip install pytest-xdist)")
        return
    parallel, _ = timed(folder, "-n", "2")
    print(f"-n 2:   {parallel:.1f} s = {parallel / serial:.2f}x the serial time (goal <= 0.6x)")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
