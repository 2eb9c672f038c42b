"""Procedures run live against a real `lab up` (every device its own process, Type I over paced
ptys through taps, Type II over TCP through taps): three shipped procedures pass; a procedure
that must fail fails with the expectation and what was seen, in the JUnit, JSON and HTML; and
however a run ends -- a failure, Ctrl-C -- the faults it set are cleared."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir
from tests.lab.conftest import RunningLab, request, start_lab, wait_until

SHIPPED = data_dir("emulators") / "procedures"
LIVE = ("route_set.yaml", "route_conflict_refused.yaml", "type1_comm_error.yaml")


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    """The procedures' quiet lab (no train, no ARS), renamed, in real processes."""
    tmp = tmp_path_factory.mktemp("proclab")
    text = (SHIPPED / "labs" / "quiet.yaml").read_text(encoding="utf-8")
    line = (data_dir("emulators") / "lines" / "reference.yaml").resolve()
    text = text.replace("lab: quiet", "lab: proclab").replace(
        "../../lines/reference.yaml", str(line)
    )
    (tmp / "proclab.yaml").write_text(text, encoding="utf-8")
    with start_lab(tmp, "proclab", path=tmp / "proclab.yaml") as running:
        yield running


def test_run(lab: RunningLab, *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return lab.cli("test", "run", "--live", "proclab", "--no-colour", *args, timeout=timeout)


test_run.__test__ = False  # type: ignore[attr-defined]  # a helper, not a test


def faulted(lab: RunningLab, link: str) -> bool:
    """Whether the link's tap has any fault on (a cut, bit errors, loss, noise, delay)."""
    status = request(lab.links[link]["tap"], {"cmd": "status"})["status"]
    keys = ("cut", "ber", "loss", "noise", "delay")
    return bool(status["cut"]) or any(d[k] for d in status["directions"].values() for k in keys)


def test_three_shipped_procedures_pass_live(lab: RunningLab, tmp_path: Path) -> None:
    junit, report = tmp_path / "junit.xml", tmp_path / "report"
    done = test_run(lab, *(str(SHIPPED / p) for p in LIVE), "--junit", str(junit),
                    "--report", str(report))  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    cases = ET.parse(junit).getroot().findall("./testsuite/testcase")
    assert [c.get("name") for c in cases] == ["route-set", "route-conflict-refused",
                                              "type1-comm-error"]  # fmt: skip
    assert all(not list(c.iter("failure")) and not list(c.iter("error")) for c in cases)
    page = (report / "type1-comm-error.html").read_text(encoding="utf-8")
    assert 'download="type1-comm-error-st22-atc.pcapng"' in page  # the run's capture, attached
    assert "data:application/vnd.tcpdump.pcap;base64," in page and "<svg" in page
    assert "link st22-atc cleared" in page  # the cut was taken off at the end
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    assert results["summary"] == {"pass": 3, "fail": 0, "error": 0, "skipped": 0}
    assert not faulted(lab, "st22-atc")


INTERVALS = ("direction_handover.yaml", "direction_opposing_refused.yaml",
             "interval_link_cut.yaml", "trailed_point_reported.yaml")  # fmt: skip


def test_the_interval_and_point_procedures_pass_live(lab: RunningLab, tmp_path: Path) -> None:
    """The permission handed over between two IXL processes over their tapped Type I link, an
    opposing departure refused, that link cut with a train in the interval and restored, and a
    trailed point reported and repaired -- each leaves the lab as it found it (18 holding 1820,
    point 31 normal), so they run one after the other on one lab."""
    report = tmp_path / "report"
    done = test_run(lab, *(str(SHIPPED / p) for p in INTERVALS), "--report", str(report),
                    "--json", timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    results = json.loads(done.stdout)["procedures"]
    assert [(p["id"], p["verdict"]) for p in results] == [
        ("direction-handover", "pass"), ("direction-opposing-refused", "pass"),
        ("interval-link-cut", "pass"), ("trailed-point-reported", "pass")]  # fmt: skip
    cut = next(p for p in results if p["id"] == "interval-link-cut")
    assert "link iv1820 cleared" in cut["cleared"]
    assert not faulted(lab, "iv1820")


FAILING = """\
id: must-fail
title: expects a signal to clear with no route set
verifies: [IXL-INV-03]  # the reports say what failed
tags: [negative]
setup: {lab: 'QUIET'}
steps:
  - fault: link st18-io ber 1e-4
  - expect: ctc 18 route 0111 is unset
  - expect: ctc 18 signal 01 is G
    within: 2s
  - expect: ctc 18 signal 01 is R
"""


def test_a_procedure_that_must_fail_fails_and_every_report_says_why(
    lab: RunningLab, tmp_path: Path
) -> None:
    path = tmp_path / "must_fail.yaml"
    path.write_text(
        FAILING.replace("QUIET", str(SHIPPED / "labs" / "quiet.yaml")), encoding="utf-8"
    )
    junit, report = tmp_path / "junit.xml", tmp_path / "report"
    done = test_run(lab, str(path), "--junit", str(junit), "--report", str(report), "--json")
    assert done.returncode == 1, done.stdout + done.stderr
    why = "step 3 (expect: ctc 18 signal 01 is G) failed: not within 2 s; seen: R"
    result = json.loads(done.stdout)["procedures"][0]
    assert result["verdict"] == "fail" and result["message"] == why
    assert [s["verdict"] for s in result["steps"]] == ["pass", "pass", "fail", "skipped"]
    assert result["cleared"] == ["link st18-io cleared"]
    failure = ET.parse(junit).getroot().find("./testsuite/testcase/failure")
    assert failure is not None and failure.get("message") == why
    assert "seen instead: R" in (failure.text or "")
    page = (report / "must-fail.html").read_text(encoding="utf-8")
    assert '<span class="v fail">FAIL</span>' in page and "not within 2 s" in page
    assert not faulted(lab, "st18-io")  # the bit errors were cleared


INTERRUPTED = """\
id: interrupted
title: cut a link, then wait long
verifies: [T1-LINK-01]  # Ctrl-C clears the faults
tags: [negative]
setup: {lab: 'QUIET'}
steps:
  - fault: link st20-io cut
  - wait: 600s
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_ctrl_c_ends_the_run_with_128_plus_the_signal_and_clears_its_faults(
    lab: RunningLab, tmp_path: Path, sig: signal.Signals
) -> None:
    """Ctrl-C (or SIGTERM) as the run has its fault set: exit 130 (143), the fault cleared, nothing
    on stderr but the count, and the reports written -- the procedure an error, "interrupted"."""
    path = tmp_path / "interrupted.yaml"
    path.write_text(
        INTERRUPTED.replace("QUIET", str(SHIPPED / "labs" / "quiet.yaml")), encoding="utf-8"
    )
    report = tmp_path / "new" / "report"
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "test", "run", "--live", "proclab",
         "--no-colour", str(path), "--junit", str(tmp_path / "j.xml"), "--report", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "KTCS_BENCH_RUN_DIR": str(lab.run_dir)},
    )  # fmt: skip
    try:
        wait_until("the run cut the link", lambda: faulted(lab, "st20-io"),
                   timeout=90)  # fmt: skip
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig, out + err  # 130 Ctrl-C, 143 SIGTERM
    assert not faulted(lab, "st20-io")
    assert "cleared: link st20-io cleared" in out
    assert err.splitlines() == ["0 of 1 procedures passed, 1 in error (interrupted)"]
    suite = ET.parse(tmp_path / "j.xml").getroot().find("./testsuite")
    assert suite is not None and (suite.get("errors"), suite.get("failures")) == ("1", "0")
    error = suite.find("./testcase/error")
    assert error is not None and (error.get("message") or "").startswith("interrupted")
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    assert results["summary"] == {"pass": 0, "fail": 0, "error": 1, "skipped": 0}
    assert (report / "interrupted.html").is_file()
