"""SPEC §10, issue 26: one lab file, three hosts, one `ktcs-bench lab up LAB --host NAME` per host.

The reference lab (CTC, track circuits, stations 18, 20, 22, its three timetable trains under ARS)
is spread over three network namespaces on one bridge: `central` runs the CTC, the rails, the
trains and station 18; `west` station 20; `east` station 22. Each host's command runs inside its
namespace with a run folder of its own (nothing shared but the lab file and a copy of its token),
and the hosts start in the reverse of the order the links need (east, west, then central). The
interval links iv1820 and iv2022 join IXLs on different hosts: Type I over RFC 2217. Then `east`'s
network is cut and restored, and the lab is taken down host by host.

Needs root and iproute2 (CI has both): without them it fails, saying so (`netns.require_netns`).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.runtime import ensure_token, read_token

from .conftest import lab_file, request, stop_group, wait_until
from .netns import Net, require_netns

NAME = "spread"
HOSTS = {"central": 1, "west": 20, "east": 22}  # host -> last byte of its address
STATION_HOST = {18: "central", 20: "west", 22: "east"}
CONTROL = 7700  # each host's lab control port; its services on the ports after it
START = 120.0  # s for the lab to come up (three hosts' commands, 14 device processes)
RECOVER = 120.0  # s for the links to come back after the network does


def host_of(device: str) -> str:
    """Where the test places each device of the reference lab."""
    match = re.search(r"(18|20|22)$", device)
    return STATION_HOST[int(match.group(1))] if match else "central"


def spread_lab(tmp: Path, addresses: dict[str, str]) -> Path:
    """The reference lab, with its trains, placed on the hosts: `hosts:` with each namespace's
    address, every device's `host:` a host's name (the trains: central's address, which is
    accepted too)."""
    path = lab_file(tmp, NAME, trains=True)
    text = path.read_text(encoding="utf-8")

    def place(m: re.Match[str]) -> str:
        device = m.group(1)
        host = addresses["central"] if device.startswith("train") else host_of(device)
        return f"  {device}:{m.group(2)}{{{m.group(3)}host: {host}}}"

    text, placed = re.subn(r"^  (\w+):(\s*)\{(.*)host: 127\.0\.0\.1\}", place, text, flags=re.M)
    assert placed == 14, text
    hosts = "".join(f"  {h}: {{address: {a}, control: {CONTROL}}}\n" for h, a in addresses.items())
    text = text.replace("\ndevices:\n", f"\nhosts:\n{hosts}devices:\n")
    path.write_text(text, encoding="utf-8")
    return path


class Spread:
    """The three hosts, each with its run folder and token copy, and its `lab up`."""

    def __init__(self, net: Net, tmp: Path) -> None:
        self.net, self.tmp = net, tmp
        self.addresses = {h: net.host(h, last) for h, last in HOSTS.items()}
        self.lab = spread_lab(tmp, self.addresses)
        self.procs: dict[str, subprocess.Popen[str]] = {}
        first = self.run_dir("central")
        first.mkdir(mode=0o700)
        self.token = ensure_token(first / "lab.token")  # made on one host, copied to the others
        for host in HOSTS:
            folder = self.run_dir(host)
            folder.mkdir(mode=0o700, exist_ok=True)
            if host != "central":
                fd = os.open(folder / "lab.token", os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
                with os.fdopen(fd, "w") as f:
                    f.write(self.token + "\n")

    def run_dir(self, host: str) -> Path:
        return self.tmp / f"run-{host}"

    def env(self, host: str) -> dict[str, str]:
        return {**os.environ, "KTCS_BENCH_RUN_DIR": str(self.run_dir(host))}

    def up(self, host: str) -> None:
        argv = [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(self.lab),
                "--host", host, "--token-file", str(self.run_dir(host) / "lab.token"),
                "--json", "--interval", "5"]  # fmt: skip
        self.procs[host] = subprocess.Popen(
            self.net.inside(host, *argv), stdout=subprocess.DEVNULL,
            stderr=open(self.tmp / f"{host}.stderr", "w"),  # noqa: SIM115 -- the child's
            text=True, start_new_session=True, env=self.env(host),
        )  # fmt: skip

    def cli(self, host: str, *args: str) -> subprocess.CompletedProcess[str]:
        """`ktcs-bench ARGS` run on `host` (in its namespace, with its run folder)."""
        argv = [sys.executable, "-m", "ktcs_bench.cli.main", *args]
        return subprocess.run(self.net.inside(host, *argv), capture_output=True, text=True,
                              timeout=90, env=self.env(host))  # fmt: skip

    def status_on(self, host: str) -> dict[str, Any]:
        done = self.cli(host, "lab", "status", NAME, "--json")
        assert done.returncode == 0, f"lab status on {host}: {done.stderr}"
        return json.loads(done.stdout)  # type: ignore[no-any-return]

    def state(self, host: str) -> dict[str, Any]:
        path = self.run_dir(host) / "labs" / NAME / "lab.json"
        return json.loads(path.read_text(encoding="utf-8"))  # type: ignore[no-any-return]

    def ask(self, host: str, obj: dict[str, Any]) -> dict[str, Any]:
        """A command to host `host`'s lab runner, from outside the hosts (the bridge)."""
        return request(f"{self.addresses[host]}:{CONTROL}", obj, timeout=30, token=self.token)

    def whole(self, host: str) -> dict[str, Any] | None:
        """The whole lab's status from host `host`'s runner; None while it does not answer."""
        try:
            return self.ask(host, {"cmd": "status"})["status"]  # type: ignore[no-any-return]
        except OSError:
            return None

    def device(self, name: str, obj: dict[str, Any]) -> dict[str, Any]:
        address = self.state(host_of(name))["devices"][name]["control"]
        return request(address, obj, token=self.token)

    def logs(self) -> str:
        out = []
        for path in sorted(self.tmp.glob("*.stderr")):
            out.append(f"--- {path.name}\n{path.read_text(errors='replace')[-3000:]}")
        return "\n".join(out)

    def close(self) -> None:
        pids = []
        for host in HOSTS:
            try:
                pids += [d.get("pid") for d in self.state(host)["devices"].values()]
            except (OSError, ValueError, KeyError):
                pass
        for proc in self.procs.values():
            stop_group(proc, 30)
        for pid in pids:  # nothing a host's lab started may outlive the test
            if pid:
                try:
                    os.killpg(pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass


@pytest.fixture
def spread(tmp_path: Path) -> Iterator[Spread]:
    require_netns()  # fails, never skips, without root or iproute2
    net = Net()
    hosts = None
    try:
        hosts = Spread(net, tmp_path)
        yield hosts
    finally:
        if hosts is not None:
            hosts.close()
        net.close()


def whole_lab_up(status: dict[str, Any] | None) -> bool:
    """Every host reached and done starting, every device alive, every link up, every station synced at the CTC
    in center mode with every point detected."""
    if status is None:
        return False
    stations = status.get("stations") or {}
    return (
        all(h["reached"] and h["up"] for h in status["hosts"].values())
        and all(d["alive"] for d in status["devices"].values())
        and all(lk["up"] for lk in status["links"].values())
        and sorted(map(int, stations)) == [18, 20, 22]
        and all(
            s["link"] == "up"
            and s["synced"]
            and s["mode"] == "center"
            and "failed" not in s["points"].values()
            for s in stations.values()
        )
    )


def _if_up(status: dict[str, Any]) -> dict[str, Any] | None:
    return status if whole_lab_up(status) else None


def test_reference_lab_over_three_hosts_one_command_each(spread: Spread) -> None:
    for host in ("east", "west", "central"):  # the CTC and the rails last: any order will do
        spread.up(host)
    try:
        wait_until(
            "the whole lab up, seen from central's runner",
            lambda: whole_lab_up(spread.whole("central")),
            timeout=START,
        )
    except (AssertionError, OSError) as exc:
        raise AssertionError(f"{exc}\n{spread.logs()}") from None
    devices = {d for d in spread.state("central")["devices"]} | {
        d for h in ("west", "east") for d in spread.state(h)["devices"]
    }
    assert len(devices) == 14  # each device runs on exactly one host ...
    for host in HOSTS:
        assert {d for d in spread.state(host)["devices"]} == {
            d for d in devices if host_of(d) == host
        }, host  # ... the one the lab file places it on

    # `lab status` run on each host shows the whole lab, every device and link with its host
    for host in HOSTS:
        status = wait_until(f"the whole lab up in `lab status` on {host}",
                            lambda h=host: _if_up(spread.status_on(h)), timeout=60)  # fmt: skip
        assert status["host"] == host
        assert set(status["devices"]) == devices
        for name, entry in status["devices"].items():
            assert entry["host"] == host_of(name) and entry["alive"], (host, name, entry)
        assert status["links"]["iv1820"]["host"] == "central"  # the tap on end a's host
        assert status["links"]["iv2022"]["host"] == "west"
        assert status["links"]["st22-ctc"]["host"] == "east"
    # the interval links cross hosts over RFC 2217: the tap opens the IXL's pty served there
    links = spread.ask("central", {"cmd": "map"})["links"]
    ends = {e["link"]: e for e in links}
    assert ends["iv1820"]["b_end"] == f"rfc2217://{spread.addresses['west']}:{CONTROL + 1}"
    assert ends["iv2022"]["b_end"] == f"rfc2217://{spread.addresses['east']}:{CONTROL + 1}"
    assert ends["iv2022 rfc2217"]["host"] == "east"
    assert spread.device("ixl20", {"cmd": "status"})["status"]["links"]["east"]
    assert spread.device("ixl22", {"cmd": "status"})["status"]["links"]["west"]

    # a device of another host restarted from central: west's runner does it, on a new pty that
    # west's RFC 2217 server serves again, and the interval link comes back through it
    before = spread.state("west")["devices"]["ixl20"]["pid"]
    done = spread.cli("central", "lab", "restart", "ixl20", "--lab", NAME)
    assert done.returncode == 0 and "ixl20: restarted" in done.stdout, done.stderr
    assert spread.state("west")["devices"]["ixl20"]["pid"] != before
    wait_until("the whole lab up again after ixl20's restart",
               lambda: whole_lab_up(spread.whole("central")), timeout=RECOVER)  # fmt: skip

    def ctc_equals_ixl(st: int) -> bool:
        view = spread.device("ctc", {"cmd": "show", "station": st})
        ixl = spread.device(f"ixl{st}", {"cmd": "status"})["status"]["ctc_state"]
        return bool(view["summary"]["synced"]) and list(view["state"].values()) == [
            ixl[k] for k in sorted(ixl, key=int)
        ]

    # east's network cable out: its links go down, seen from either side
    spread.net.cut("east", up=False)
    wait_until("the CTC declares station 22 down",
               lambda: spread.device("ctc", {"cmd": "show", "station": 22})["summary"]["link"] == "down")  # fmt: skip
    wait_until("IXL 20 loses its Type I link to IXL 22 (RFC 2217 across the cut)",
               lambda: not spread.device("ixl20", {"cmd": "status"})["status"]["links"]["east"])  # fmt: skip
    status = spread.ask("central", {"cmd": "status"})["status"]
    assert not status["hosts"]["east"]["reached"], status["hosts"]
    assert not any(status["links"][n]["up"] for n in ("st22-ctc", "st22-atc", "st22-io", "iv2022"))
    assert all(status["links"][n]["up"] for n in ("st18-ctc", "st20-ctc", "iv1820"))
    inside = spread.status_on("east")  # east, cut off, still shows its own part, the rest unreached
    assert inside["hosts"]["east"]["reached"] and not inside["hosts"]["central"]["reached"]
    assert inside["devices"]["ixl22"]["alive"] and not inside["links"]["st22-ctc"]["up"]

    # the cable back in: the links come back by themselves, the CTC's view equals IXL 22's state
    spread.net.cut("east", up=True)
    wait_until("the whole lab up again after the cut",
               lambda: whole_lab_up(spread.whole("central")), timeout=RECOVER)  # fmt: skip
    wait_until("the CTC's view of station 22 equals IXL 22's state", lambda: ctc_equals_ixl(22))

    # `lab down` on east ends east's part only; `lab down --all` on west ends the others
    east_pids = [d["pid"] for d in spread.state("east")["devices"].values()]
    done = spread.cli("east", "lab", "down", NAME)
    assert done.returncode == 0, done.stderr
    assert spread.procs["east"].wait(60) == 0
    assert not any(_alive(p) for p in east_pids)
    status = spread.ask("central", {"cmd": "status"})["status"]
    assert not status["hosts"]["east"]["reached"] and status["hosts"]["west"]["reached"]
    assert status["devices"]["ixl20"]["alive"] and not status["devices"]["ixl22"]["alive"]
    left = [d["pid"] for h in ("central", "west") for d in spread.state(h)["devices"].values()]
    done = spread.cli("west", "lab", "down", NAME, "--all")
    assert done.returncode == 0, done.stderr
    assert "on host central: stopping" in done.stdout, done.stdout
    for host in ("central", "west"):
        assert spread.procs[host].wait(60) == 0, host
    assert not any(_alive(p) for p in left)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"


def test_lab_status_across_hosts_needs_the_same_token(spread: Spread, tmp_path: Path) -> None:
    """A host whose token is not the lab's is not let in: the others show it unreached."""
    (spread.run_dir("west") / "lab.token").unlink()
    ensure_token(spread.run_dir("west") / "lab.token")  # another secret
    assert read_token(spread.run_dir("west") / "lab.token") != spread.token
    for host in ("central", "west"):
        spread.up(host)

    def refused() -> dict[str, Any] | None:
        """Central's view once west's runner answers it and refuses its token."""
        status = spread.whole("central")
        west = None if status is None else status["hosts"]["west"]["error"]
        return status if "wrong token" in str(west) else None

    status = wait_until("west's runner refusing central's token", refused, timeout=START)
    assert status["hosts"]["central"]["reached"] and not status["hosts"]["west"]["reached"]
    assert not any(d["alive"] for n, d in status["devices"].items() if host_of(n) == "west")
