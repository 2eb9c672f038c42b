"""SPEC §10: a lab spread over several hosts. Four Linux network namespaces (the CTC and the IXLs
of stations 18, 20, 22, each station with its ATC and trackside I/O on its own "computer"), joined
by veth pairs on a bridge; a station's network is cut and restored by taking its veth down.
Nothing assumes loopback: the IXLs reach the CTC at its own address."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from .conftest import request, wait_until
from .netns import Net, require_netns

STATIONS = (18, 20, 22)


class Hosts:
    def __init__(self, net: Net) -> None:
        self.net = net
        self.procs: list[subprocess.Popen[str]] = []
        self.ready: dict[str, dict[str, Any]] = {}

    def start(self, host: str, name: str, *args: str) -> dict[str, Any]:
        ns = self.net.hosts[host][0]
        proc = subprocess.Popen(
            ["ip", "netns", "exec", ns, sys.executable, "-m", "ktcs_bench.cli.main", "emulator",
             *args, "--name", name, "--unpaced"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
        )  # fmt: skip
        self.procs.append(proc)
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line, f"{name} did not start in namespace {ns}"
        self.ready[name] = json.loads(line)
        return self.ready[name]

    def ask(self, host: str, name: str, obj: dict[str, Any]) -> dict[str, Any]:
        """A control-port request made from inside `host`'s namespace (it may be cut off)."""
        code = ("import asyncio, json, sys; from ktcs_bench.transport import jsonlines; "
                "h, _, p = sys.argv[1].rpartition(':'); "
                "print(json.dumps(asyncio.run(jsonlines.request(h, int(p), json.loads(sys.argv[2])))))")  # fmt: skip
        out = subprocess.run(
            ["ip", "netns", "exec", self.net.hosts[host][0], sys.executable, "-c", code,
             self.ready[name]["control"], json.dumps(obj)],
            capture_output=True, text=True, timeout=30, check=True,
        )  # fmt: skip
        return json.loads(out.stdout)  # type: ignore[no-any-return]

    def close(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


@pytest.fixture
def multihost() -> Iterator[Hosts]:
    require_netns()  # fails, never skips, without root or iproute2
    net = Net()
    hosts = Hosts(net)
    try:
        ctc_ip = net.host("ctc", 1)
        for st in STATIONS:
            net.host(f"st{st}", st)
        hosts.start(
            "ctc", "ctc", "ctc", "--listen", f"{ctc_ip}:5000", "--control", f"{ctc_ip}:5001"
        )
        for st in STATIONS:
            ip = net.hosts[f"st{st}"][2]
            ixl = hosts.start(
                f"st{st}", f"ixl{st}", "ixl", "--station", str(st), "--control", f"{ip}:5001",
                "--link", f"ctc=tcp://{ctc_ip}:5000", "--link", "atc=pty", "--link", "io=pty",
            )  # fmt: skip
            hosts.start(f"st{st}", f"atc{st}", "atc", "--station", str(st), "--control", f"{ip}:5002",
                        "--link", f"ixl={ixl['ptys']['atc']}")  # fmt: skip
            hosts.start(f"st{st}", f"io{st}", "trackside", "--station", str(st),
                        "--control", f"{ip}:5003", "--link", f"ixl={ixl['ptys']['io']}")  # fmt: skip
        yield hosts
    finally:
        hosts.close()
        net.close()


def test_ctc_and_three_ixls_on_four_hosts_survive_a_cut_network(multihost: Hosts) -> None:
    hosts, net = multihost, multihost.net
    ctc = hosts.ready["ctc"]["control"]

    def station(st: int) -> dict[str, Any]:
        return request(ctc, {"cmd": "show", "station": st})  # type: ignore[no-any-return]

    def equal(st: int) -> bool:
        view = station(st)
        ixl = request(hosts.ready[f"ixl{st}"]["control"], {"cmd": "status"})["status"]["ctc_state"]
        return view["summary"]["synced"] and list(view["state"].values()) == [
            ixl[k] for k in sorted(ixl, key=int)
        ]

    for st in STATIONS:
        wait_until(f"station {st} synced at the CTC across the network", lambda st=st: equal(st))
        peer = station(st)["summary"]
        assert peer["link"] == "up"
    # the CTC sees each IXL at its own address, not loopback
    log = request(ctc, {"cmd": "status"})["status"]["stations"]
    assert set(map(int, log)) == set(STATIONS)

    net.cut("st20", up=False)
    wait_until(
        "the CTC declares station 20 down (T_MAX)", lambda: station(20)["summary"]["link"] == "down"
    )
    assert station(18)["summary"]["link"] == "up" and station(22)["summary"]["link"] == "up"
    # change station 20's state while it is cut off: its ATC dies, its track circuits go occupied
    atc20 = next(p for p in hosts.procs if "atc20" in p.args)  # type: ignore[operator]
    os.killpg(atc20.pid, signal.SIGKILL)
    wait_until("IXL 20 notices its ATC link failing (asked from inside its own host)",
               lambda: not hosts.ask("st20", "ixl20", {"cmd": "status"})["status"]["links"]["atc"])  # fmt: skip
    net.cut("st20", up=True)
    wait_until(
        "station 20 reconnects and resyncs",
        lambda: station(20)["summary"]["link"] == "up",
        timeout=60,
    )
    wait_until("the CTC's view equals IXL 20's state after the cut", lambda: equal(20), timeout=60)
    assert station(20)["summary"]["occupied"], "the outage's change (all occupied) reached the CTC"
