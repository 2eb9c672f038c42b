"""The lab file's `hosts:` (SPEC §10): each device placed on a named host, every problem one
ConfigError naming the file and key path; where a spread lab's taps and services are
(`lab.multihost.Placement`), from the lab file alone; `lab up --host` refusing what it cannot do."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from ktcs_bench.errors import ConfigError, UsageError
from ktcs_bench.lab.multihost import Placement
from ktcs_bench.lab.topology import load_lab

from .test_external import write_lab

HOSTS = (
    "hosts:\n"
    "  a: {address: 10.0.0.1, control: 7700}\n"
    "  b: {address: 10.0.0.2, control: 7800, token_file: b.token}\n"
)
DEVICES = (
    "  ctc: {kind: ctc, host: a}\n"
    "  tc: {kind: trackcircuit, host: a}\n"
    "  ixl18: {kind: ixl, station: 18, host: a}\n"
    "  atc18: {kind: atc, station: 18, host: 10.0.0.2}\n"
    "  ixl20: {kind: ixl, station: 20, host: b}\n"
)
LINKS = (
    "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
    "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n"
    "  - {name: st20-ctc, type: type2, a: ixl20, b: ctc}\n"
    "  - {name: iv1820, type: type1, a: ixl18, b: ixl20}\n"
)


def spread_lab(tmp: Path, hosts: str = HOSTS, devices: str = DEVICES) -> Path:
    return write_lab(tmp, "spread", f"{devices}{hosts}", LINKS)  # `hosts:` after the devices


def test_devices_are_placed_on_named_hosts(tmp_path: Path) -> None:
    lab = load_lab(spread_lab(tmp_path))
    assert lab.hosts["b"].control == 7800 and lab.hosts["b"].token_file == tmp_path / "b.token"
    assert lab.devices["ixl20"].host == "10.0.0.2"  # a host's name: its address
    assert lab.devices["atc18"].host == "10.0.0.2"  # an address of a host stays accepted
    place = Placement(lab)
    assert [place.host_of(n) for n in lab.devices] == ["a", "a", "a", "b", "b"]
    # each host's services on the ports after its control port, in a fixed order
    assert place.ports == {
        "a": {"control": 7700, "type2": 7701, "rails": 7702},
        "b": {"control": 7800, "rfc2217 st18-atc": 7801, "rfc2217 iv1820": 7802},
    }
    # host a runs the taps of the links whose end a is there; their ends on b are reached over
    # RFC 2217, the CTC at its fixed Type II port
    view = place.view("a")
    assert [lk.name for lk in view.links] == ["st18-ctc", "st18-atc", "iv1820"]
    assert view.type2_port == 7701 and view.devices["tc"].options["port"] == 7702
    ixl20, atc18 = view.devices["ixl20"].external, view.devices["atc18"].external
    assert ixl20 is not None and ixl20.serial == "rfc2217://10.0.0.2:7802"
    assert atc18 is not None and atc18.serial == "rfc2217://10.0.0.2:7801"
    view = place.view("b")
    assert [lk.name for lk in view.links] == ["st20-ctc"]
    ctc = view.devices["ctc"].external
    assert ctc is not None and ctc.address == ("10.0.0.1", 7701)
    assert set(view.devices) == {"atc18", "ixl20", "ctc"}


def test_a_real_device_on_another_host_is_opened_by_the_tap_not_served(tmp_path: Path) -> None:
    """An external ATC (behind a serial server) whose `host:` is not its IXL's: the tap on the
    IXL's host opens its own URL; no host serves it over RFC 2217."""
    devices = DEVICES.replace(
        "atc18: {kind: atc, station: 18, host: 10.0.0.2}",
        "atc18: {kind: atc, station: 18, host: b, external: {serial: 'rfc2217://10.0.0.9:4000'}}",
    )
    place = Placement(load_lab(spread_lab(tmp_path, devices=devices)))
    assert "rfc2217 st18-atc" not in place.ports["b"]
    atc18 = place.view("a").devices["atc18"].external
    assert atc18 is not None and atc18.serial == "rfc2217://10.0.0.9:4000"


@pytest.mark.parametrize(
    ("hosts", "devices", "place", "words"),
    [
        ("hosts: [a, b]\n", DEVICES, "hosts", "mapping NAME -> {address, control}"),
        ("hosts:\n  a: 10.0.0.1\n", DEVICES, "hosts.a", "mapping {address"),
        ("hosts:\n  a: {address: 10.0.0.1}\n", DEVICES, "hosts.a.control", "missing key"),
        ("hosts:\n  a: {address: 10.0.0.1, control: 0}\n", DEVICES, "hosts.a.control",
         "out of range"),
        ("hosts:\n  a: {address: 10.0.0.1, control: 65535}\n", DEVICES, "hosts.a.control",
         "no port after it"),
        ("hosts:\n  a: {address: '10.0.0.1:80', control: 7700}\n", DEVICES, "hosts.a.address",
         "the address alone"),
        ("hosts:\n  a: {address: 'fd00::1', control: 7700}\n", DEVICES, "hosts.a.address",
         "an IPv6 address is not taken here"),
        ("hosts:\n  a: {address: 'a b', control: 7700}\n", DEVICES, "hosts.a.address",
         "host name or IP address"),
        ("hosts:\n  a: {address: 10.0.0.1, control: 7700, port: 1}\n", DEVICES, "hosts.a.port",
         "unknown key"),
        ("hosts:\n  a: {address: 10.0.0.1, control: 7700}\n  b: {address: 10.0.0.1, control: 7700}\n",
         DEVICES, "hosts.b.address", "host a's address too"),
        ("hosts:\n  a: {address: 10.0.0.1, control: 7700, token_file: ''}\n", DEVICES,
         "hosts.a.token_file", "not empty"),
        (HOSTS, DEVICES.replace("host: b}", "host: c}"), "devices.ixl20.host",
         "'c' is not a host of the lab (a, b)"),
        (HOSTS, DEVICES.replace(", host: a}\n  ixl18", "}\n  ixl18"), "devices.tc.host",
         "name the one this device runs on"),
    ],
)  # fmt: skip
def test_a_bad_hosts_entry_is_one_error_naming_the_key(
    tmp_path: Path, hosts: str, devices: str, place: str, words: str
) -> None:
    path = spread_lab(tmp_path, hosts, devices)
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    assert err.value.file == str(path) and err.value.place == place, str(err.value)
    assert words in err.value.problem, str(err.value)


def test_placement_refuses_what_it_cannot_do(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    single = write_lab(tmp_path, "single", "  ctc: {kind: ctc}\n", "  []\n")
    with pytest.raises(UsageError, match="names no hosts"):
        Placement(load_lab(single))
    place = Placement(load_lab(spread_lab(tmp_path)))
    with pytest.raises(UsageError, match=r"no host 'c' in lab spread \(a, b\)"):
        place.view("c")
    monkeypatch.delenv("KTCS_BENCH_TOKEN_FILE", raising=False)
    with pytest.raises(UsageError, match="the same token"):
        place.token_file("a", None)
    assert place.token_file("b", None) == tmp_path / "b.token"
    assert place.token_file("a", "/x/lab.token") == Path("/x/lab.token")
    crowded = spread_lab(tmp_path, HOSTS.replace("control: 7800", "control: 65534"))
    with pytest.raises(UsageError, match="past 65535"):
        _ = Placement(load_lab(crowded)).ports


def test_lab_up_on_the_wrong_host_or_a_taken_port_is_a_usage_error(tmp_path: Path) -> None:
    """`lab up --host a` where a's address is not this machine's, or where a's control port is
    taken: exit 2 saying so, before any device starts."""
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}
    token = ["--token-file", str(tmp_path / "lab.token")]
    lab = spread_lab(tmp_path, HOSTS.replace("10.0.0.1", "192.0.2.1"))  # TEST-NET-1: not ours
    done = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(lab),
                           "--host", "a", *token], capture_output=True, text=True, timeout=60,
                          env=env)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "192.0.2.1, which is not an address of this machine" in done.stderr, done.stderr
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        hosts = HOSTS.replace("10.0.0.1, control: 7700", f"127.0.0.1, control: {port}")
        done = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up",
                               str(spread_lab(tmp_path, hosts)), "--host", "a", *token],
                              capture_output=True, text=True, timeout=60, env=env)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert f"cannot serve the lab control on 127.0.0.1:{port}" in done.stderr, done.stderr
    assert not list((tmp_path / "run").glob("labs/*/logs/*.log")), "a device was started"


def test_lab_up_host_usage_errors_exit_2(tmp_path: Path) -> None:
    single = write_lab(tmp_path, "single", "  ctc: {kind: ctc}\n", "  []\n")
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}
    env.pop("KTCS_BENCH_TOKEN_FILE", None)
    for args, words in (
        ([str(single), "--host", "a"], "names no hosts"),
        ([str(spread_lab(tmp_path)), "--host", "a"], "--token-file"),
        ([str(single), "--token-file", "x"], "--token-file goes with --host"),
        ([str(single), "--host", "a", "--in-process"], "not with --in-process"),
        ([str(spread_lab(tmp_path))], "--host NAME"),
    ):
        done = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", *args],
                              capture_output=True, text=True, timeout=60, env=env)  # fmt: skip
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
        assert "Traceback" not in done.stderr
