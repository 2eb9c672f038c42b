"""Issue 16: a Type I device behind Debian's `ser2net` (RFC 2217) on another host, reached by the
lab across the network as real labs reach a serial device. The hosts are Linux namespaces made
without root where user namespaces are allowed (`unshare --user --map-root-user`); what runs in
them, and what is checked, is `ser2net_hosts.py`.

This test is never skipped: ser2net, util-linux's `unshare`/`nsenter` and iproute2 are part of the
set-up (`.ci/system-deps`), and a machine that refuses the namespaces fails here, saying so."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# a user namespace (root inside, no privilege outside), a network namespace (the lab's host) and
# a pid namespace whose pid 1 is the driver: when it ends, the kernel ends all it started
UNSHARE = ["unshare", "--user", "--map-root-user", "--net", "--pid", "--fork", "--kill-child",
           "--mount-proc"]  # fmt: skip
TIMEOUT = 300.0


def test_a_type1_device_behind_ser2net_on_another_host(tmp_path: Path) -> None:
    missing = [tool for tool in ("ser2net", "unshare", "nsenter", "ip") if not shutil.which(tool)]
    if missing:
        pytest.fail(f"{', '.join(missing)} not installed: `make setup` installs them "
                    "(.ci/system-deps, as root); this test needs them and is not skipped")  # fmt: skip
    probe = subprocess.run([*UNSHARE, "ip", "link", "add", "p0", "type", "veth", "peer", "p1"],
                           capture_output=True, text=True, timeout=30)  # fmt: skip
    if probe.returncode != 0:
        pytest.fail(
            "this machine refuses the namespaces the test stands two hosts up in "
            f"({' '.join(UNSHARE)} ...: {probe.stderr.strip()}). They need user namespaces "
            "(sysctl kernel.unprivileged_userns_clone=1; on Ubuntu 24.04 also "
            "kernel.apparmor_restrict_unprivileged_userns=0), or root outside a container "
            "that filters unshare(2)"
        )
    proc = subprocess.Popen(
        [*UNSHARE, sys.executable, "-m", "tests.lab.ser2net_hosts", str(tmp_path)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:  # --kill-child: unshare's end takes the driver and all it started
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    logs = "".join(
        f"\n--- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
        for p in sorted(tmp_path.glob("*.log")) + sorted(tmp_path.glob("*.stderr"))
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{err[-6000:]}{logs}"
    seen = json.loads(out.strip().splitlines()[-1])
    assert seen["alive"] and seen["after_outage"]["atc18"]["open"], seen
    assert seen["code_TC1853A"][1] > seen["code_TC1853A"][0], seen
