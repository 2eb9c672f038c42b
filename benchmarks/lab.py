"""SPEC §8 lab figure: CTC route command -> proceed indication back at the CTC, minus the emulated
physical times (point throw, wire time). Goal: <= 50 ms added by the software.

The real lab runs (`ktcs-bench lab up`, every device its own process, taps in every link). The
CTC process times each route itself (`timed_route`: CONTROL sent -> CONTROL_RESULT -> the entry
signal's proceed indication), so no polling error enters. Routes alternate between 01->11 (point 31
normal) and 01->12 (point 31 reverse), so every second route throws the point (its throw time comes
from the station data and is subtracted); each route is cancelled before the next.

Two runs: Type I unpaced (wire time zero: what remains is the software's own time) and paced at
9600 bit/s (wire time included, shown for comparison).

Run: python benchmarks/lab.py [--routes 20]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from ktcs_bench.datafiles import data_dir
from ktcs_bench.runtime import read_token
from ktcs_bench.station.loader import load_line
from ktcs_bench.transport import jsonlines

ROUTES = [("01", "11", "0111"), ("01", "12", "0112")]


def req(address: str, obj: dict[str, Any], token: str, timeout: float = 60) -> dict[str, Any]:
    host, _, port = address.rpartition(":")
    return asyncio.run(jsonlines.request(host, int(port), obj, timeout=timeout, token=token))


def run_lab(routes: int, unpaced: bool) -> list[float]:
    tmp = Path(tempfile.mkdtemp(prefix="ktcs-lab-bench-"))
    text = (data_dir("emulators") / "labs" / "reference.yaml").read_text()
    line_path = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("lab: reference", "lab: bench").replace("port: 8020", "port: 0")
    text = text.replace("line: ../lines/reference.yaml", f"line: {line_path}")
    # the figure is of routes on an empty line: without the timetable, its trains and ARS
    text = "".join(
        ln
        for ln in text.splitlines(keepends=True)
        if not ln.startswith(("timetable:", "ars:")) and "{kind: train," not in ln
    )
    (tmp / "bench.yaml").write_text(text)
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp / "run")}
    argv = [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(tmp / "bench.yaml"), "--json",
            "--interval", "30"] + (["--unpaced"] if unpaced else [])  # fmt: skip
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, text=True, env=env, start_new_session=True
    )
    try:
        assert proc.stdout is not None
        json.loads(proc.stdout.readline())
        # drain the status stream: a full pipe would block `lab up` (and its Ctrl-C handling)
        threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
        state = json.loads((tmp / "run" / "labs" / "bench" / "lab.json").read_text())
        ctc = state["devices"]["ctc"]["control"]
        token = read_token(Path(state["token_file"]))  # the lab's: its control ports need it
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            st = req(ctc, {"cmd": "show", "station": 18}, token)["summary"]
            if st["synced"] and not st["occupied"] and st["points"]["31"].startswith("normal"):
                break
            time.sleep(0.2)
        line = load_line()
        throw = next(p.throw_time_s for p in line.station(18).points if p.name == "31")
        overheads = []
        position = "normal"
        for k in range(routes):
            entry, exit_, name = ROUTES[k % 2]
            wants = "normal" if exit_ == "11" else "reverse"
            answer = req(
                ctc, {"cmd": "timed_route", "station": 18, "entry": entry, "exit": exit_}, token
            )
            if not answer.get("ok"):
                raise SystemExit(f"route {name} refused: {answer}")
            physical = throw if wants != position else 0.0
            position = wants
            overheads.append(answer["proceed_s"] - physical)
            if os.environ.get("KTCS_BENCH_VERBOSE"):
                print(
                    f"  {name}: result {answer['result_s'] * 1e3:.1f} ms, proceed {answer['proceed_s'] * 1e3:.1f} ms, throw {physical} s",
                    flush=True,
                )
            req(
                ctc,
                {"cmd": "route", "action": "cancel", "station": 18, "entry": entry, "exit": exit_},
                token,
            )
            while True:  # released, and the signal back at stop as the CTC sees it
                summary = req(ctc, {"cmd": "show", "station": 18}, token)["summary"]
                if name not in summary["routes"] and summary["signals"][entry] == "R":
                    break
                time.sleep(0.05)
        return overheads
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(60)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--routes", type=int, default=20)
    args = ap.parse_args()
    for unpaced in (True, False):
        o = run_lab(args.routes, unpaced)
        label = "Type I unpaced (no wire time)" if unpaced else "Type I paced at 9600 bit/s"
        med, worst = statistics.median(o) * 1e3, max(o) * 1e3
        verdict = ("met" if med <= 50 else "NOT met") if unpaced else "wire time included"
        print(f"route command -> proceed indication at the CTC, minus point throw, {label}: "
              f"median {med:.1f} ms, max {worst:.1f} ms over {len(o)} routes  (goal <= 50 ms: {verdict})")  # fmt: skip


if __name__ == "__main__":
    main()
