"""The runtime folder of the user who runs the bench, and the identity of the processes in it.

The folder is $KTCS_BENCH_RUN_DIR, else $XDG_RUNTIME_DIR/ktcs-bench, else
/tmp/ktcs-bench-<uid>. Labs keep their state there (`labs/NAME/lab.json`, logs, captures, the
lab's token), named taps announce themselves there (`taps/NAME.json`). It is made 0700; one that
another user owns is refused (it could hold a token planted for us).

A process is named by its pid and its start time (clock ticks since boot, /proc/PID/stat): pids
are reused, so a pid alone left in a state file by a process that died may name a stranger.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import Any

from ktcs_bench.errors import UsageError


def run_dir() -> Path:
    if "KTCS_BENCH_RUN_DIR" in os.environ:
        return Path(os.environ["KTCS_BENCH_RUN_DIR"])
    if "XDG_RUNTIME_DIR" in os.environ:
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "ktcs-bench"
    return Path(tempfile.gettempdir()) / f"ktcs-bench-{os.getuid()}"


def private_dir(path: Path) -> Path:
    """`path` made (0700) if missing; a UsageError if it is not a folder of ours that only we
    may write. Its parents are made as needed (the run folder itself included)."""
    root = run_dir()
    root.mkdir(mode=0o700, parents=True, exist_ok=True)
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    for p in (root, path):
        st = p.lstat()
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            raise UsageError(f"{p} is not a folder of user {os.getuid()}: refusing to use it")
        if st.st_mode & 0o022:
            raise UsageError(f"{p} may be written by others (mode {st.st_mode & 0o777:o})")
    return path


def process_started(pid: int) -> int | None:
    """The start time of process `pid` (clock ticks since boot), None if there is no such live
    process (a zombie counts as gone)."""
    if pid <= 0:
        return None
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rpartition(")")[2].split()  # after "pid (comm)": state is field 3
    if len(fields) < 20 or fields[0] in ("Z", "X"):
        return None
    return int(fields[19])  # field 22, starttime


def process_alive(pid: int, started: int | None = None) -> bool:
    """Process `pid` runs, and is the one that started at `started` (when given)."""
    now = process_started(pid)
    return now is not None and (started is None or now == started)


def this_process() -> dict[str, Any]:
    """{"pid", "started"} of the calling process, for a state file."""
    return {"pid": os.getpid(), "started": process_started(os.getpid())}
