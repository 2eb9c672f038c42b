"""Hosts for the multi-host tests (SPEC §10): Linux network namespaces on one bridge, each on an
address of its own, cut off and reconnected by taking its veth down and up. They need root and
iproute2 (CI runs as root and installs it: `.ci/system-deps`); without them the test FAILS,
saying so -- it is never skipped, so a machine that cannot run it cannot pass it silently."""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid

import pytest

SUBNET = "10.77.{}"


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


def sh(*args: str) -> None:
    done = subprocess.run(args, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")


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
