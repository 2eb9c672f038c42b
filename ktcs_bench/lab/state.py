"""A lab's runtime folder (`runtime.run_dir()/labs/NAME/`): its state file `lab.json` (the lab
process, its control port, every device's process, addresses and ptys, the link map), its logs and
captures.

`lab up` writes the state as soon as it starts and again as each device comes up, so a lab that
dies however it dies -- SIGKILL included -- leaves behind what is needed to clean up after it:
`clean_up_after` stops the devices it left (each named by pid and start time, so a recycled pid is
never killed), drops its taps from the registry and removes the state. `lab down` and the next
`lab up` of the same lab do that.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.runtime import process_alive, run_dir
from ktcs_bench.tap.registry import known_taps

STOP_GRACE = 5.0  # s a leftover device has to stop on SIGTERM before SIGKILL


def lab_dir(name: str) -> Path:
    return run_dir() / "labs" / name


def state_file(name: str) -> Path:
    return lab_dir(name) / "lab.json"


def read_state(name: str) -> dict[str, Any] | None:
    """The state lab `name` left, None if it has none."""
    try:
        state = json.loads(state_file(name).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {"lab": name, "pid": 0, "devices": {}}  # unreadable: a lab that is not there
    return state if isinstance(state, dict) else {"lab": name, "pid": 0, "devices": {}}


def write_state(name: str, state: dict[str, Any]) -> None:
    path = state_file(name)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(state, indent=1), encoding="utf-8")
    tmp.replace(path)


def is_alive(state: dict[str, Any]) -> bool:
    return process_alive(int(state.get("pid") or 0), state.get("started"))


def running_labs() -> list[dict[str, Any]]:
    """The state (lab.json) of every lab that is up on this machine, for tools that attach to one."""
    out = []
    for path in sorted((run_dir() / "labs").glob("*/lab.json")):
        state = read_state(path.parent.name)
        if state is not None and is_alive(state):
            out.append(state)
    return out


def attach(name: str) -> dict[str, Any]:
    """The state of running lab `name`: UsageError if it is not up, PeerError if it died."""
    state = read_state(name)
    if state is None:
        raise UsageError(f"lab {name} is not running (no {state_file(name)})")
    if not is_alive(state):
        raise PeerError(
            f"lab {name} is not running: its process {state.get('pid')} died without stopping "
            f"it; `ktcs-bench lab down {name}` cleans up what it left"
        )
    return state


def clean_up_after(name: str) -> list[str]:
    """If lab `name` died and left state behind: stop the devices still running from it, drop its
    taps from the registry, remove the state. Returns what was done (nothing: nothing was left).
    UsageError if the lab is up."""
    state = read_state(name)
    if state is None:
        return []
    if is_alive(state):
        raise UsageError(f"lab {name} is up (pid {state['pid']}); `ktcs-bench lab down {name}`")
    left = {
        n: (int(d["pid"]), d.get("started"))
        for n, d in (state.get("devices") or {}).items()
        if isinstance(d, dict) and d.get("pid") and process_alive(int(d["pid"]), d.get("started"))
    }
    _stop(left)
    known_taps()  # drops the announcements of taps whose process (the dead lab) is gone
    state_file(name).unlink(missing_ok=True)
    done = [f"lab {name} had died (pid {state.get('pid')}); its state is removed"]
    if left:
        done.append(f"stopped what it left running: {', '.join(sorted(left))}")
    return done


def _stop(procs: dict[str, tuple[int, Any]]) -> None:
    """SIGTERM each (its process group: a device is a session leader), SIGKILL what is left after
    the grace period; returns when all are gone."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid, started in procs.values():
            if process_alive(pid, started):
                try:
                    os.killpg(pid, sig)
                    os.killpg(pid, signal.SIGCONT)  # a stopped process acts on SIGTERM too
                except (ProcessLookupError, PermissionError):
                    pass
        end = time.monotonic() + STOP_GRACE
        while time.monotonic() < end:
            if not any(process_alive(pid, started) for pid, started in procs.values()):
                return
            time.sleep(0.05)
