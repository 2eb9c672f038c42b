"""Issue 15 §4 scale figures: generated lines of N = 3, 10, 20 stations (`line generate`).

Live: `ktcs-bench lab up` on the generated lab file (every device its own process, Type I paced at
9600 bit/s through taps, Type II through taps), timed from the launch of `lab up` until every
station is synced at the CTC in center mode with its Type II link up and its IXL's Type I links
(ATC, trackside) up. Then the memory of the lab: the resident set (VmRSS) of `lab up` (which also
runs the taps, one thread each) and of every process under it, summed; the proportional set size
(Pss, shared pages split between the processes that share them) beside it, since a sum of RSS
counts the interpreter's shared pages once per process. Goals: 20 stations live in <= 20 s and
<= 1.5 GB.

Grouped (issue 26 §1): the same lab with `lab up --group station`, a station's IXL, ATC and
trackside in one process (Type I still over the taps' ptys), forked from one template process
that has loaded the lab, so 20 stations are 23 processes, not 62. Both figures are printed, one row each (`--groups`). Goal: 20 stations live in <= 8 s and
<= 1.0 GB summed RSS.

Where the time goes: `lab up` starts the devices of each step together (every ATC and trackside,
then every IXL), a few at a time as the machine has cores, so the start-up is about the CPU all the
devices need to start, shared by the cores. The figures printed under the table split it: the
time until `lab up` has started every device and answers, the time from then until the stations
are synced, and the CPU time each device had used when the lab was ready, by kind (from /proc).

The devices run as an installed package's do, from compiled bytecode: the benchmark compiles
ktcs_bench's modules first (pip compiles a package's on install). Where PYTHONDONTWRITEBYTECODE is
set and nothing was compiled, every device process compiles its ~130 modules from source, about
0.4 s of CPU each.

Virtual time: the same lab in one process on the virtual clock, as `lab simulate` runs it (issue 15
§2): VIRTUAL_S of virtual time against the wall and against this process's CPU time, start-up
included, for each line of the table and for the lines of `--virtual` (default 43 stations, the
goal of issue 26 §4: >= 50x real time), each printed with the load average beside it.

Run: python benchmarks/scale.py [--stations 3 10 20] [--groups none station] [--virtual 43]
                                [--timeout 300]
"""

from __future__ import annotations

import argparse
import asyncio
import compileall
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import ktcs_bench
from ktcs_bench.lab.generate import write_line
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.runtime import process_alive, read_token
from ktcs_bench.station.generate import LAB_FILE
from ktcs_bench.transport import jsonlines

GOAL_STATIONS = 20
VIRTUAL_GOAL = (43, 50.0)  # issue 26 §4: a generated 43-station line >= 50x real time (by CPU)
GOALS = {"none": (20.0, 1.5e9), "station": (8.0, 1.0e9)}  # --group: (ready within s, RSS bytes)
VIRTUAL_S = 600.0  # virtual seconds of each generated lab in one process
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
IDLE_SAMPLE_S = 5.0  # how long the ready lab's CPU use is sampled


def _request(address: str, obj: dict[str, Any], token: str) -> dict[str, Any]:
    host, _, port = address.rpartition(":")
    return asyncio.run(jsonlines.request(host, int(port), obj, timeout=10, token=token))


def _descendants(root: int) -> list[int]:
    """`root` and every live process under it (by parent pid, from /proc)."""
    parent: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rpartition(")")[2].split()
            except OSError:
                continue
            parent[int(entry.name)] = int(fields[1])
    out, todo = [root], [root]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def _memory_kb(pid: int) -> tuple[int, int]:
    """(VmRSS, Pss) of `pid` in kB; (0, 0) if it has gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except OSError:
        return 0, 0

    def field(text: str, key: str) -> int:
        line = next((ln for ln in text.splitlines() if ln.startswith(key + ":")), f"{key}: 0 kB")
        return int(line.split()[1])

    return field(status, "VmRSS"), field(rollup, "Pss")


def _ready(state: dict[str, Any], stations: list[int], token: str) -> bool:
    """Every station synced at the CTC in center mode, its IXL's links all up."""
    devices = state["devices"]
    seen = _request(devices["ctc"]["control"], {"cmd": "status"}, token)["status"]["stations"]
    if sorted(int(s) for s in seen) != stations or not all(
        s["link"] == "up" and s["synced"] and s["mode"] == "center" for s in seen.values()
    ):
        return False
    for st in stations:
        ixl = _request(devices[f"ixl{st}"]["control"], {"cmd": "status"}, token)["status"]
        if ixl["mode"] != "center" or not ixl["links"] or not all(ixl["links"].values()):
            return False
    return True


def live(n: int, timeout: float, group: str = "none") -> dict[str, Any]:
    """One live run of the generated N-station lab, its devices grouped in processes as `lab up
    --group GROUP` groups them: its timings and memory."""
    tmp = Path(tempfile.mkdtemp(prefix=f"ktcs-scale-{n}-"))
    write_line(n, tmp / "line")
    run_dir = tmp / "run"
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(run_dir)}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # see the module's doc: run as installed
    argv = [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(tmp / "line" / LAB_FILE),
            "--json", "--interval", "3600", "--group", group]  # fmt: skip
    t0 = time.monotonic()
    boot = _boot_time()
    err = open(tmp / "lab.stderr", "w")  # noqa: SIM115 -- closed below
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=err, text=True, env=env,
                            start_new_session=True)  # fmt: skip
    state: dict[str, Any] = {"devices": {}}
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        if not first:
            raise SystemExit(f"lab up failed: {(tmp / 'lab.stderr').read_text()[-2000:]}")
        t_up = time.monotonic() - t0
        # drain its status lines: one blocked on a full pipe would not stop on SIGTERM
        threading.Thread(target=proc.stdout.read, daemon=True).start()
        state = json.loads((run_dir / "labs" / f"line{n}" / "lab.json").read_text())
        token = read_token(Path(state["token_file"]))
        stations = sorted(
            int(name.removeprefix("ixl")) for name in state["devices"] if name.startswith("ixl")
        )
        while not _ready(state, stations, token):
            if time.monotonic() - t0 > timeout:
                raise SystemExit(f"{n} stations: not ready within {timeout:g} s")
            time.sleep(0.1)
        t_ready = time.monotonic() - t0
        pids = _descendants(proc.pid)
        cpu_at_ready = {pid: _cpu_ticks(pid) / CLOCK_TICKS for pid in pids}
        memory = {pid: _memory_kb(pid) for pid in pids}
        cpu0, w0 = sum(_cpu_ticks(p) for p in pids), time.monotonic()
        time.sleep(IDLE_SAMPLE_S)
        idle_cpu = (sum(_cpu_ticks(p) for p in pids) - cpu0) / CLOCK_TICKS / (time.monotonic() - w0)
        kinds = {
            int(d["pid"]): "station group" if "process" in d else name.rstrip("0123456789")
            for name, d in state["devices"].items()
        }
        by_kind: dict[str, list[int]] = {}
        cpu_by_kind: dict[str, list[float]] = {}
        for pid, (rss, _) in memory.items():
            other = "group template" if group == "station" else "other"  # forks the groups
            kind = "lab up + taps" if pid == proc.pid else kinds.get(pid, other)
            by_kind.setdefault(kind, []).append(rss)
            cpu_by_kind.setdefault(kind, []).append(cpu_at_ready[pid])
        spawned = [boot + d["started"] / CLOCK_TICKS - t0 for d in state["devices"].values()]
        return {
            "stations": n,
            "group": group,
            "devices": len(state["devices"]),
            "processes": len(pids),
            "up_s": t_up,
            "ready_s": t_ready,
            "rss_bytes": sum(r for r, _ in memory.values()) * 1024,
            "pss_bytes": sum(p for _, p in memory.values()) * 1024,
            "rss_by_kind_mb": {k: (len(v), statistics.mean(v) / 1024) for k, v in by_kind.items()},
            "cpu_to_ready_s": {k: statistics.mean(v) for k, v in cpu_by_kind.items()},
            "cpu_total_s": sum(cpu_at_ready.values()),
            "last_spawn_s": max(spawned),
            "idle_cpu": idle_cpu,
            "data_load_s": _data_load_s(tmp / "line" / LAB_FILE),
        }
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(120)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        err.close()
        for d in state["devices"].values():  # they stop with their lab; none may outlive it
            if d.get("pid") and process_alive(d["pid"], d.get("started")):
                os.killpg(d["pid"], signal.SIGKILL)
        shutil.rmtree(tmp, ignore_errors=True)


def _cpu_ticks(pid: int) -> int:
    """utime + stime of `pid` in clock ticks; 0 if it has gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    except OSError:
        return 0
    return int(fields[11]) + int(fields[12])


_DATA_LOAD = """
import sys, time
from ktcs_bench.lab.topology import load_lab
t = time.perf_counter()
load_lab(sys.argv[1]).load_line()
print(time.perf_counter() - t)
"""


def _data_load_s(lab_file: Path) -> float:
    """What every device process does first: load the lab file (which loads and checks the line)
    and then the line (`ktcs-bench emulator`), in a fresh process (a process keeps a line it
    loaded). Best of three."""
    runs = [subprocess.run([sys.executable, "-c", _DATA_LOAD, str(lab_file)], check=True,
                           capture_output=True, text=True).stdout for _ in range(3)]  # fmt: skip
    return min(float(r) for r in runs)


def _boot_time() -> float:
    """The monotonic clock's reading at boot, so /proc start times (ticks since boot) compare."""
    uptime = float(Path("/proc/uptime").read_text().split()[0])
    return time.monotonic() - uptime


def virtual_speed_up(n: int, seconds: float = VIRTUAL_S) -> tuple[float, float]:
    """Virtual seconds per wall second, and per CPU second of this process, of the generated
    N-station lab in one process on the virtual clock, as `lab simulate` runs it (issue 15 §2,
    goal >= 50x at 20 stations): `seconds` of virtual time, start-up included, captures and
    events written. On a machine others share the wall figure is what it took beside them, the
    CPU figure what it cost."""
    tmp = Path(tempfile.mkdtemp(prefix=f"ktcs-scale-virtual-{n}-"))
    try:
        write_line(n, tmp / "line")
        lab = InProcessLab(tmp / "line" / LAB_FILE, seed=1, out=tmp / "out")
        t0, c0 = time.monotonic(), time.process_time()
        lab.run(lambda lab: lab.sleep(seconds))
        return seconds / (time.monotonic() - t0), seconds / (time.process_time() - c0)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--stations", type=int, nargs="*", default=[3, 10, 20])
    ap.add_argument("--groups", nargs="+", choices=tuple(GOALS), default=list(GOALS),
                    help="lab up --group of each live run (default: both, one row each)")  # fmt: skip
    ap.add_argument("--timeout", type=float, default=300.0, help="give up on a lab after (s)")
    ap.add_argument("--virtual", type=int, nargs="*", default=[VIRTUAL_GOAL[0]],
                    help="stations of further lines measured in one process on the virtual "
                         f"clock only (default {VIRTUAL_GOAL[0]}; none: --virtual)")  # fmt: skip
    args = ap.parse_args()
    compileall.compile_dir(Path(ktcs_bench.__file__).parent, quiet=1)  # as pip install would
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    head = (f"{'stations':>8} {'group':>7} {'devices':>7} {'procs':>5} {'all started':>11} {'ready':>7} "
            f"{'RSS sum':>9} {'Pss sum':>9} {'virtual':>9} {'(by CPU)':>9}")  # fmt: skip
    print(head, flush=True)
    rows = []
    for n in args.stations:
        v, v_cpu = virtual_speed_up(n)
        for group in args.groups:
            r = live(n, args.timeout, group)
            rows.append(r)
            print(f"{n:>8} {group:>7} {r['devices']:>7} {r['processes']:>5} {r['up_s']:>10.1f}s "
                  f"{r['ready_s']:>6.1f}s {r['rss_bytes'] / 1e6:>7.0f}MB {r['pss_bytes'] / 1e6:>7.0f}MB "
                  f"{f'{v:.0f}x':>9} {f'{v_cpu:.0f}x':>9}  load {os.getloadavg()[0]:.1f}",
                  flush=True)  # fmt: skip
    print(f"virtual: {VIRTUAL_S:.0f} s of the lab in one process on the virtual clock (lab simulate), "
          "speed-up against the wall (and against the CPU time it used), start-up included")  # fmt: skip
    for r in rows:
        what = f"{r['stations']} stations, --group {r['group']}"
        kinds = ", ".join(
            f"{k} {c}x{mb:.0f}MB" for k, (c, mb) in sorted(r["rss_by_kind_mb"].items())
        )
        cpu = ", ".join(f"{k} {s:.2f}s" for k, s in sorted(r["cpu_to_ready_s"].items()))
        print(f"{what}: RSS by process kind (count x mean): {kinds}")
        print(f"{what}: the last device spawned at {r['last_spawn_s']:.1f} s; "
              f"CPU used until ready, {r['cpu_total_s']:.1f} s in all, a process by kind: {cpu}")  # fmt: skip
        print(f"{what}: a device's data load (lab file + line, YAML): "
              f"{r['data_load_s']:.2f} s; the ready lab idling uses {r['idle_cpu']:.2f} CPU")  # fmt: skip
    for n in args.virtual:
        v, v_cpu = virtual_speed_up(n)
        goal = (f" (goal >= {VIRTUAL_GOAL[1]:g}x: {'met' if v_cpu >= VIRTUAL_GOAL[1] else 'NOT met'})"
                if n == VIRTUAL_GOAL[0] else "")  # fmt: skip
        print(f"virtual, {n} stations: {v:.1f}x real time by the wall, {v_cpu:.1f}x by CPU{goal}, "
              f"load average {os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    for big in (r for r in rows if r["stations"] == GOAL_STATIONS):
        goal_s, goal_bytes = GOALS[big["group"]]
        t_ok, m_ok = big["ready_s"] <= goal_s, big["rss_bytes"] <= goal_bytes
        print(f"goal {GOAL_STATIONS} stations live (--group {big['group']}) in <= {goal_s:g} s: "
              f"{'met' if t_ok else 'NOT met'} ({big['ready_s']:.1f} s); "
              f"<= {goal_bytes / 1e9:g} GB: {'met' if m_ok else 'NOT met'} "
              f"(RSS sum {big['rss_bytes'] / 1e9:.2f} GB, Pss sum {big['pss_bytes'] / 1e9:.2f} GB)")  # fmt: skip


if __name__ == "__main__":
    main()
