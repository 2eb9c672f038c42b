"""`ktcs-bench threats --target TAP` against a link the test builds by hand, as an engineer wires
a device the bench cannot read: `tap run` between an IXL and an ATC process. The verdicts come from
the wire alone and the outcome is reported as not observed; an IXL that never NAKs is caught."""

from __future__ import annotations

import json
import signal
import subprocess
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest

from ktcs_bench.tap.client import TapClient
from tests.conformance.conftest import CLI, Proc, cli, spawn  # noqa: F401 -- the fixture
from tests.tap.test_taps import EchoServer

TYPE1 = ["repetition", "deletion", "insertion", "corruption"]


def _link(spawn: Callable[..., Proc], name: str, *ixl_args: str) -> None:  # noqa: F811
    tap = spawn("tap", "run", "--pty", "--names", "ixl,atc", "--name", name, "--json")
    ptys = tap.ready["paths"]
    rails = spawn("emulator", "trackcircuit", "--listen", "127.0.0.1:0").ready["listen"]
    spawn("emulator", "atc", "--station", "18", "--unpaced", "--link", f"ixl={ptys['atc']}",
          "--link", f"rails=tcp://{rails}")  # fmt: skip
    spawn("emulator", "ixl", "--station", "18", "--unpaced", "--link", f"atc={ptys['ixl']}",
          *ixl_args)  # fmt: skip


@pytest.fixture(autouse=True)
def _run_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("KTCS_BENCH_RUN_DIR", str(tmp_path / "run"))  # taps announce themselves here


def test_wire_only_target(spawn: Callable[..., Proc]) -> None:  # noqa: F811
    _link(spawn, "bench-ixl-atc")
    run = cli("threats", "--target", "bench-ixl-atc", "--json", timeout=180)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    report = json.loads(run.stdout)
    (target,) = report["targets"]
    assert target["dut"] == "ixl" and target["peer"] == "atc" and target["application"] is None
    by_name = {r["threat"]: r for r in report["results"]}
    for name in TYPE1:
        r = by_name[name]
        assert r["ran"] and r["caught"], r
        assert r["safe"] is None and r["outcome"].startswith("not observed"), r
    for name in ("resequencing", "delay", "masquerade"):
        assert not by_name[name]["ran"] and "Type II" in by_name[name]["outcome"]
    assert "REQUEST_ALL sent" in " ".join(by_name["insertion"]["evidence"])


def test_a_device_without_nak_is_caught(spawn: Callable[..., Proc], tmp_path: Path) -> None:  # noqa: F811
    _link(spawn, "bench-no-nak", "--fault", "no-nak")
    junit = tmp_path / "threats.xml"
    run = cli("threats", "--target", "bench-no-nak", "--threat", "corruption", "--json",
              "--junit", str(junit))  # fmt: skip
    assert run.returncode == 1, run.stdout[-4000:] + run.stderr[-2000:]
    (r,) = json.loads(run.stdout)["results"]
    assert r["threat"] == "corruption" and not r["caught"]
    assert "NAK reason 1: no" in r["evidence"][0]
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "1"
    (case,) = suite.findall("testcase")
    failure = case.find("failure")
    assert case.get("name") == "corruption" and failure is not None
    assert failure.get("message", "").startswith("not caught")


def test_no_such_tap(tmp_path: Path) -> None:
    run = cli("threats", "--target", "nowhere")
    assert run.returncode == 2 and "no tap named 'nowhere'" in run.stderr
    run = cli("threats", "--target", "127.0.0.1:1")
    assert run.returncode == 3 and "cannot reach the tap" in run.stderr
    echo = EchoServer()  # something else listening: named as not a tap, no traceback
    try:
        host, port = echo.address
        run = cli("threats", "--target", f"{host}:{port}")
    finally:
        echo.close()
    assert run.returncode == 3 and "is not a tap's control port" in run.stderr, run.stderr
    assert "Traceback" not in run.stderr


def test_wire_only_type2_target(spawn: Callable[..., Proc]) -> None:  # noqa: F811
    """A TCP tap in front of a CTC the bench does not read: resequencing, delay and masquerade
    judged on the wire alone."""
    ctc = spawn("emulator", "ctc", "--listen", "127.0.0.1:0").ready["listen"]
    tap = spawn("tap", "run", "--tcp", "127.0.0.1:0", ctc, "--names", "ixl,ctc", "--name",
                "bench-ixl-ctc", "--json")  # fmt: skip
    host, port = tap.ready["listen"]
    spawn("emulator", "ixl", "--station", "18", "--link", f"ctc=tcp://{host}:{port}")
    run = cli("threats", "--target", "bench-ixl-ctc", "--json", timeout=180)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    report = json.loads(run.stdout)
    assert report["targets"][0]["dut"] == "ctc" and report["targets"][0]["application"] is None
    by_name = {r["threat"]: r for r in report["results"]}
    for name in ("resequencing", "delay", "masquerade"):
        r = by_name[name]
        assert r["ran"] and r["caught"] and r["safe"] is None, r
    evidence = " ".join(by_name["masquerade"]["evidence"])
    assert "IDENT station 18 → refused" in evidence and "connection kept" in evidence
    assert "ctc closed" in by_name["delay"]["evidence"][0]


def test_interrupted_campaign_leaves_no_fault_behind(spawn: Callable[..., Proc]) -> None:  # noqa: F811
    """Ctrl-C while the deletion threat holds the link cut: the campaign clears the tap."""
    _link(spawn, "bench-interrupted")
    campaign = subprocess.Popen([*CLI, "threats", "--target", "bench-interrupted", "--threat",
                                 "deletion"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    try:
        with TapClient("bench-interrupted") as tap:

            def cut() -> bool:
                return any(d["cut"] for d in tap.status()["directions"].values())

            end = time.monotonic() + 30
            while not cut():
                assert time.monotonic() < end and campaign.poll() is None, "the cut never came"
                time.sleep(0.1)
            campaign.send_signal(signal.SIGINT)
            assert campaign.wait(20) == 130
            assert not cut()
    finally:
        if campaign.poll() is None:
            campaign.kill()
        campaign.communicate()
