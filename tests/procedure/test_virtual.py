"""The whole shipped suite, each procedure on its own lab in one process on the virtual clock
(`--virtual`, the default): every procedure passes, and the reports carry every one."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir

SHIPPED = sorted((data_dir("emulators") / "procedures").glob("*.yaml"))


def test_the_shipped_suite_passes_in_virtual_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    junit, report = tmp_path / "junit.xml", tmp_path / "report"
    code = main(["test", "run", *map(str, SHIPPED), "--junit", str(junit), "--report",
                 str(report), "--no-colour"])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0, out
    cases = ET.parse(junit).getroot().findall("./testsuite/testcase")
    assert len(cases) == len(SHIPPED) >= 10
    assert not [c.get("name") for c in cases if list(c.iter("failure")) or list(c.iter("error"))]
    results = json.loads((report / "results.json").read_text(encoding="utf-8"))
    assert {p["mode"] for p in results["procedures"]} == {"virtual"}
    run = next(p for p in results["procedures"] if p["id"] == "train-run-18-22")
    assert run["duration_s"] > 600  # ten minutes of the lab's clock ...
    assert {"1001", "1003"} <= set(run["trains"])  # ... the timetable trains' runs recorded
    page = (report / "train-run-18-22.html").read_text(encoding="utf-8")
    assert 'alt="speed-distance" src="data:image/png;base64,' in page
    assert (report / "index.html").is_file()
