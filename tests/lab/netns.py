"""Hosts on one machine, for the tests of devices on other hosts, as Linux namespaces.

Two hosts (`test_ser2net.py`, `test_labgrid.py`), made without root where user namespaces are
allowed:

A test runs its driver module as `UNSHARE python -m tests.lab.DRIVER TMP` (`run_driver`): in
there the driver is the lab's host -- a network namespace of its own (`LAB_IP`) and pid 1 of a pid
namespace, so when it ends, however it ends, the kernel ends every process it started and the
namespaces go with them. `DeviceHost` is the second host, a network namespace (`DEVICE_IP`)
joined to the first by a veth pair. The driver prints one JSON line of what it saw and exits 0,
or prints why it failed and exits 1 (`driver_main`).

These tests are never skipped: the tools are part of the set-up (`.ci/system-deps`, `make
setup`), and a machine that lacks them or refuses the namespaces fails, saying so
(`require_namespaces`).

Several hosts on a bridge (`test_multihost.py`, `test_multihost_lab.py`; `Net`), each a network
namespace on an address of its own, cut off and reconnected by taking its veth down and up. They
need root and iproute2; without them the test fails (`require_netns`)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import traceback
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAB_IP, DEVICE_IP = "10.99.0.1", "10.99.0.2"
SUBNET = "10.77.{}"  # `Net`: a bridge's /24
# a user namespace (root inside, no privilege outside), a network namespace (the lab's host) and
# a pid namespace whose pid 1 is the driver: when it ends, the kernel ends all it started
UNSHARE = ["unshare", "--user", "--map-root-user", "--net", "--pid", "--fork", "--kill-child",
           "--mount-proc"]  # fmt: skip


def require_namespaces(tools: tuple[str, ...] = ()) -> None:
    """Fail (never skip) when a tool the test needs is missing or the machine refuses the
    namespaces: `make setup` installs the tools, CI runs as root."""
    needed = ("unshare", "nsenter", "ip", *tools)
    missing = [tool for tool in needed if not shutil.which(tool)]
    if missing:
        pytest.fail(f"{', '.join(missing)} not installed: `make setup` installs them "
                    "(.ci/system-deps and the venv's extras); this test needs them and is not "
                    "skipped")  # fmt: skip
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


def run_driver(module: str, tmp: Path, timeout: float) -> dict[str, Any]:
    """Run `python -m module TMP` as the lab's host in its namespaces; what it saw (its last JSON
    line). A failure shows its stderr and the logs it left in TMP."""
    proc = subprocess.Popen(
        [*UNSHARE, sys.executable, "-m", module, str(tmp)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:  # --kill-child: unshare's end takes the driver and all it started
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    logs = "".join(
        f"\n--- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
        for p in sorted(tmp.glob("*.log")) + sorted(tmp.glob("*.stderr"))
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{err[-6000:]}{logs}"
    return json.loads(out.strip().splitlines()[-1])  # type: ignore[no-any-return]


def driver_main(main: Callable[[Path], dict[str, Any]]) -> None:
    """A driver's `__main__`: one JSON line of what `main(TMP)` saw and exit 0, or its traceback
    and exit 1."""
    try:
        print(json.dumps(main(Path(sys.argv[1]))), flush=True)
    except BaseException:  # noqa: BLE001 - reported to the test, which fails with it
        traceback.print_exc()
        sys.exit(1)
    sys.exit(0)


def sh(*args: str, env: dict[str, str] | None = None) -> str:
    """Run a command; its stdout, or RuntimeError with its stderr."""
    done = subprocess.run(args, capture_output=True, text=True, timeout=60,
                          env=None if env is None else {**os.environ, **env})  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")
    return done.stdout


class DeviceHost:
    """The second host: a network namespace held by a `sleep`, joined to ours by a veth pair."""

    def __init__(self, lab_ip: str = LAB_IP, device_ip: str = DEVICE_IP) -> None:
        self.procs: list[subprocess.Popen[str]] = []
        self.holder = self.spawn(["unshare", "--net", "--", "sleep", "infinity"], enter=False)
        self.pid = self.holder.pid
        sh("ip", "link", "set", "lo", "up")
        sh("ip", "link", "add", "lab0", "type", "veth", "peer", "name", "dev0")
        sh("ip", "link", "set", "dev0", "netns", str(self.pid))
        sh("ip", "addr", "add", f"{lab_ip}/24", "dev", "lab0")
        sh("ip", "link", "set", "lab0", "up")
        for cmd in (["ip", "addr", "add", f"{device_ip}/24", "dev", "dev0"],
                    ["ip", "link", "set", "dev0", "up"], ["ip", "link", "set", "lo", "up"]):  # fmt: skip
            sh(*self.inside(cmd))

    def inside(self, argv: list[str]) -> list[str]:
        return ["nsenter", "-t", str(self.pid), "-n", "--", *argv]

    def spawn(self, argv: list[str], enter: bool = True, **kw: Any) -> subprocess.Popen[str]:
        proc = subprocess.Popen(self.inside(argv) if enter else argv, text=True, **kw)
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in reversed(self.procs):
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def reachable(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=1):
            return True
    except OSError:
        return False


RAILS_PORT = 7000  # the lab's rails, where the device's-host ATC joins them
LINE = ROOT / "emulators" / "lines" / "reference.yaml"


def station18_lab(tmp: Path, name: str, atc_external: str) -> Path:
    """A lab file of station 18 whose ATC is external (`atc_external`: the inside of its
    `external: {...}`), on the rails at LAB_IP:RAILS_PORT, where the device's host joins them."""
    lab_file = tmp / f"{name}.yaml"
    lab_file.write_text(
        f"lab: {name}\nline: {LINE}\ndevices:\n"
        "  ctc:   {kind: ctc}\n"
        f"  tc:    {{kind: trackcircuit, host: {LAB_IP}, port: {RAILS_PORT}}}\n"
        "  ixl18: {kind: ixl, station: 18}\n"
        f"  atc18: {{kind: atc, station: 18, external: {{{atc_external}, rails: true}}}}\n"
        "  io18:  {kind: trackside, station: 18}\n"
        "links:\n"
        "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
        "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n"
        "  - {name: st18-io,  type: type1, a: ixl18, b: io18}\n",
        encoding="utf-8",
    )  # fmt: skip
    return lab_file


def emulated_atc(
    host: DeviceHost, tmp: Path, token: Path, rails: str, station: int = 18
) -> tuple[subprocess.Popen[str], dict[str, Any]]:
    """Station `station`'s emulated ATC on the device's host: its Type I line a pty, on the lab's
    rails at `rails` (HOST:PORT), its control port on the device's address; and its ready line
    (`ptys`, `control`)."""
    atc = host.spawn(
        [sys.executable, "-m", "ktcs_bench.cli.main", "emulator", "atc", "--station", str(station),
         "--name", f"atc{station}", "--link", "ixl=pty", "--control", f"{DEVICE_IP}:0",
         "--link", f"rails=tcp://{rails}", "--token-file", str(token)],
        stdout=subprocess.PIPE, stderr=open(tmp / "atc.log", "w"),  # noqa: SIM115
    )  # fmt: skip
    assert atc.stdout is not None
    return atc, json.loads(atc.stdout.readline())


def require_netns() -> None:
    """Fail (not skip) the calling test when this machine cannot make network namespaces."""
    missing = []
    if shutil.which("ip") is None:
        missing.append("iproute2's `ip` is not installed (`make setup` installs it, as root)")
    if os.geteuid() != 0:
        missing.append(f"the tests run as uid {os.geteuid()}, not root")
    if missing:
        pytest.fail(
            "the multi-host tests stand hosts up as network namespaces, which need root and "
            f"iproute2: {'; '.join(missing)}. CI runs them as root; this test is not skipped"
        )


class Net:
    """A bridge in the root namespace and one namespace per host, each on its own address."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:5]
        self.bridge = f"kb{tag}"
        self.hosts: dict[str, tuple[str, str, str]] = {}  # name -> (netns, veth outside, address)
        self.net = SUBNET.format(int(tag, 16) % 200 + 20)
        sh("ip", "link", "add", self.bridge, "type", "bridge")
        sh("ip", "addr", "add", f"{self.net}.254/24", "dev", self.bridge)
        sh("ip", "link", "set", self.bridge, "up")
        self.tag = tag

    def host(self, name: str, last: int) -> str:
        """A new host `name` at address NET.`last`; its address."""
        ns, out, inside = f"k{self.tag}{name}", f"k{self.tag}{name}o", f"k{self.tag}{name}i"
        address = f"{self.net}.{last}"
        sh("ip", "netns", "add", ns)
        self.hosts[name] = (ns, out, address)
        sh("ip", "link", "add", out, "type", "veth", "peer", "name", inside)
        sh("ip", "link", "set", inside, "netns", ns)
        sh("ip", "link", "set", out, "master", self.bridge)
        sh("ip", "link", "set", out, "up")
        sh("ip", "netns", "exec", ns, "ip", "addr", "add", f"{address}/24", "dev", inside)
        sh("ip", "netns", "exec", ns, "ip", "link", "set", inside, "up")
        sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        return address

    def inside(self, name: str, *argv: str) -> list[str]:
        """The command line that runs `argv` on host `name`."""
        return ["ip", "netns", "exec", self.hosts[name][0], *argv]

    def cut(self, name: str, up: bool) -> None:
        """Host `name`'s network cable out (up=False) or back in."""
        sh("ip", "link", "set", self.hosts[name][1], "up" if up else "down")

    def close(self) -> None:
        for ns, out, _ in self.hosts.values():
            subprocess.run(["ip", "link", "del", out], capture_output=True)
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        subprocess.run(["ip", "link", "del", self.bridge], capture_output=True)
