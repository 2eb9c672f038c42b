"""`ktcs-bench threats` with no target: it starts a small lab of real emulator processes with a
pty tap and a TCP tap, attacks it through the taps' control ports, and every threat is caught by
its defence with a safe application outcome."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from ktcs_bench.threats import THREATS
from tests.conformance.conftest import cli


def test_every_threat_caught_in_the_small_lab(tmp_path: Path) -> None:
    table = tmp_path / "threats.md"
    junit = tmp_path / "threats.xml"
    run = cli("threats", "--json", "--markdown", str(table), "--junit", str(junit), timeout=180)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    report = json.loads(run.stdout)
    assert [t["protocol"] for t in report["targets"]] == ["type1", "type2"]
    assert all(t["application"] == "the threat lab" for t in report["targets"])
    results = report["results"]
    assert [r["threat"] for r in results] == list(THREATS)
    for r in results:
        assert r["ran"] and r["caught"] and r["safe"] is True, r
    text = table.read_text()
    assert text.startswith("| threat |") and text.count("\n") == len(THREATS) + 2
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and (suite.get("tests"), suite.get("failures")) == ("7", "0")
    assert [c.get("name") for c in suite.findall("testcase")] == list(THREATS)
    defences = {r["threat"]: r["defence"] for r in results}
    assert defences["corruption"].startswith("CRC")
    assert defences["masquerade"].startswith("IDENT")
    assert defences["delay"].startswith("timeout")
    assert defences["deletion"].startswith("timeout")
    assert defences["repetition"].startswith("SEQ")
    assert defences["insertion"].startswith("SEQ")
    assert defences["resequencing"].startswith("SEQ")


def test_unknown_threat_is_a_usage_error() -> None:
    run = cli("threats", "--threat", "teleportation")
    assert run.returncode == 2 and "unknown threat" in run.stderr
