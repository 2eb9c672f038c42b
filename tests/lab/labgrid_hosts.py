"""A lab on one host and a shared ATC on another, reserved through a real labgrid coordinator.

Run by `test_labgrid.py` through `netns.run_driver`: this process is the lab's host (10.99.0.1),
where the labgrid coordinator runs; the device's host (10.99.0.2) runs the emulated ATC of station
18 (its Type I line a pty) and a labgrid exporter that exports that pty as a `RawSerialPort` --
served, while a place holding it is acquired, by the exporter's own ser2net over RFC 2217. The
place `atc18` is made with `labgrid-client create` / `add-match`, and the lab file names the ATC
`external: {labgrid: atc18, coordinator: ...}`. Then, each time from a real `lab up`:

- the place held by another user (alice on bench2): `lab up` exits 3 naming her; with
  `--wait-for-place --place-timeout` it gives up the same way after waiting; Ctrl-C while it
  waits ends it (exit 130), her reservation untouched;
- with `--wait-for-place` it waits, says so, and comes up when she releases it; a procedure runs
  against the lab, its route through the ATC reached through labgrid; `lab down` releases the place;
- Ctrl-C (SIGINT) of `lab up` releases it; SIGKILL of `lab up`'s whole process group releases it
  too (its keeper, in a session of its own, sees the pipe close).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from ktcs_bench.runtime import private_dir
from tests.lab.conftest import RunningLab, start_lab, wait_until
from tests.lab.netns import (
    DEVICE_IP,
    LAB_IP,
    RAILS_PORT,
    DeviceHost,
    driver_main,
    emulated_atc,
    reachable,
    station18_lab,
)  # fmt: skip

COORDINATOR_PORT = 20408
COORDINATOR = f"{LAB_IP}:{COORDINATOR_PORT}"
PLACE = "atc18"
OURS = {"LG_HOSTNAME": "labhost", "LG_USERNAME": "engineer"}  # who `lab up` is, to labgrid
ALICE = {"LG_HOSTNAME": "bench2", "LG_USERNAME": "alice"}  # another user of the same device
PROCEDURE = """\
id: labgrid-atc18
title: A route at station 18 is set and cancelled, its ATC a shared device reached through labgrid
setup:
  lab: lglab.yaml
steps:
  - expect: ixl 18 link atc is up
    within: 30s
  - ctc: route set 18 01 11
  - expect: ctc 18 signal 01 is Y,YG,G
    within: 15s
  - expect: frame st18-atc ixl18>atc18 op CHANGE
    within: 10s
    note: the route's state goes to the ATC over the serial port the labgrid exporter serves
  - expect: frame st18-atc atc18>ixl18 op ACK
    within: 10s
  - ctc: route cancel 18 01 11
  - expect: ctc 18 route 0111 is unset
    within: 15s
  - expect: ctc 18 signal 01 is R
"""


def tool(name: str) -> str:
    """A labgrid command: beside this Python (its venv), as `lab up` finds labgrid-client."""
    return str(Path(sys.executable).parent / name)


def labgrid(*args: str, who: dict[str, str] = OURS) -> subprocess.CompletedProcess[str]:
    return subprocess.run([tool("labgrid-client"), "-x", COORDINATOR, *args], capture_output=True,
                          text=True, timeout=60, env={**os.environ, **who})  # fmt: skip


def holder() -> str | None:
    """Who holds the place, as the coordinator says (`show`: `acquired: HOST/USER` or None)."""
    shown = labgrid("-p", PLACE, "show")
    assert shown.returncode == 0, shown.stderr
    found = re.search(r"^\s*acquired: (\S+)$", shown.stdout, re.M)
    assert found, shown.stdout
    return None if found.group(1) == "None" else found.group(1)


def must(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 0, f"{done.args}: exit {done.returncode}: {done.stderr}"
    return done.stdout


def lab_up(lab_file: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(lab_file), "--for", "60",
         *args], capture_output=True, text=True, timeout=90,
    )  # fmt: skip


def main(tmp: Path) -> dict[str, Any]:
    name, run_dir = "lglab", tmp / "run"
    os.environ.update({"KTCS_BENCH_RUN_DIR": str(run_dir), **OURS})
    token = private_dir(run_dir / "labs" / name) / "token"  # the lab's; the ATC shares it
    seen: dict[str, Any] = {}
    host = DeviceHost()
    coordinator = subprocess.Popen([tool("labgrid-coordinator"), "-l", COORDINATOR],
                                   stdout=open(tmp / "coordinator.log", "w"),  # noqa: SIM115
                                   stderr=subprocess.STDOUT, cwd=tmp)  # fmt: skip
    try:
        wait_until("the labgrid coordinator listening", lambda: reachable(LAB_IP, COORDINATOR_PORT))
        pty = emulated_atc(host, tmp, token, f"{LAB_IP}:{RAILS_PORT}")[1]["ptys"]["ixl"]
        exports = tmp / "exporter.yaml"
        exports.write_text(f"{PLACE}:\n  RawSerialPort:\n    port: {pty}\n    speed: 9600\n")
        host.spawn([tool("labgrid-exporter"), "-c", COORDINATOR, "--name", "devhost",
                    "--hostname", DEVICE_IP, str(exports)],
                   stdout=open(tmp / "exporter.log", "w"), stderr=subprocess.STDOUT)  # noqa: SIM115  # fmt: skip
        wait_until("the exporter's serial port at the coordinator",
                   lambda: f"devhost/{PLACE}/NetworkSerialPort" in must(labgrid("resources")))  # fmt: skip
        must(labgrid("-p", PLACE, "create"))
        must(labgrid("-p", PLACE, "add-match", f"devhost/{PLACE}/*"))
        lab_file = station18_lab(tmp, name, f"labgrid: {PLACE}, coordinator: '{COORDINATOR}'")
        procedure = tmp / "labgrid_atc18.yaml"
        procedure.write_text(PROCEDURE, encoding="utf-8")

        # held by alice: exit 3 naming her, at once or after --place-timeout
        must(labgrid("-p", PLACE, "acquire", who=ALICE))
        held = lab_up(lab_file)
        assert held.returncode == 3, (held.returncode, held.stderr)
        assert "held by bench2/alice" in held.stderr and "Traceback" not in held.stderr, held.stderr
        timed_out = lab_up(lab_file, "--wait-for-place", "--place-timeout", "1")
        assert timed_out.returncode == 3, (timed_out.returncode, timed_out.stderr)
        assert "waiting" in timed_out.stderr and "held by bench2/alice" in timed_out.stderr
        # Ctrl-C while it waits: it gives up at once (exit 130), her place untouched
        said = tmp / "waiting.stderr"
        with open(said, "w") as err:
            waiting = subprocess.Popen(
                [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(lab_file),
                 "--wait-for-place"], stdout=subprocess.DEVNULL, stderr=err,
            )  # fmt: skip
        wait_until("lab up waiting for her place", lambda: "; waiting" in said.read_text())
        waiting.send_signal(signal.SIGINT)
        assert waiting.wait(30) == 130, said.read_text()
        assert holder() == "bench2/alice"
        seen["held"] = held.stderr.strip().splitlines()[-1]

        # --wait-for-place: it waits, she releases, it comes up with the place
        failed: list[BaseException] = []

        def release_when_waiting() -> None:
            said = tmp / f"{name}.stderr"
            try:
                wait_until("lab up waiting for the place", lambda: said.is_file() and
                           "held by bench2/alice; waiting" in said.read_text())  # fmt: skip
                assert holder() == "bench2/alice"  # still hers while lab up waits
                must(labgrid("-p", PLACE, "release", who=ALICE))
            except BaseException as exc:  # noqa: BLE001 - raised in the driver's thread below
                failed.append(exc)

        releaser = threading.Thread(target=release_when_waiting)
        releaser.start()
        # a release that never came: lab up gives up after --place-timeout, and the test says why
        up_args = ("--wait-for-place", "--place-timeout", "60")
        with contextlib.ExitStack() as stack:
            try:
                lab = stack.enter_context(start_lab(tmp, name, path=lab_file, up_args=up_args))
            finally:
                releaser.join()
                if failed:
                    raise failed[0]
            assert holder() == "labhost/engineer"
            end = lab.links["st18-atc"]["b_end"]
            assert re.fullmatch(rf"rfc2217://{re.escape(DEVICE_IP)}:\d+\?ign_set_control", end), end
            done = lab.cli(
                "test", "run", "--live", name, str(procedure), "--no-colour", timeout=120
            )
            assert done.returncode == 0, done.stdout + done.stderr
            seen["procedure"] = done.stdout
            down = lab.cli("lab", "down", name)
            assert down.returncode == 0, down.stderr
            assert holder() is None, "lab down returned with the place still held"
        seen["after_down"] = holder()

        def acquired(lab: RunningLab) -> bool:
            return holder() == "labhost/engineer"

        # Ctrl-C: lab up ends 130 with the place released
        with start_lab(tmp, name, path=lab_file, ready=acquired) as lab:
            lab.proc.send_signal(signal.SIGINT)
            assert lab.proc.wait(60) == 130
            assert holder() is None, "lab up ended by Ctrl-C with the place still held"
        seen["after_sigint"] = holder()

        # SIGKILL of lab up's whole process group: its keeper releases the place alone
        with start_lab(tmp, name, path=lab_file, ready=acquired) as lab:
            os.killpg(lab.proc.pid, signal.SIGKILL)
            lab.proc.wait(30)
            wait_until("the place released after lab up's SIGKILL", lambda: holder() is None)
        seen["after_sigkill"] = holder()
        must(labgrid("-p", PLACE, "acquire", who=ALICE))  # free for anyone again
        return seen
    finally:
        host.close()
        coordinator.terminate()
        coordinator.wait(10)


if __name__ == "__main__":
    driver_main(main)
