"""`ktcs-bench trace` on results the bench really wrote: two shipped procedures and one that must
fail run in one process (`test run`, JUnit and report folder), a marked pytest run's JUnit, and a
`lab simulate` run -- the matrix lists every catalogue requirement with its status, the failing
one first, the evidence pages, and the operations no run exercised; exit 1 while one fails."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.evidence.catalogue import load_catalogue

PROCEDURES = data_dir("emulators") / "procedures"
QUIET = PROCEDURES / "labs" / "quiet.yaml"
MUST_FAIL = f"""\
id: must-fail
title: expects a signal to clear with no route set
verifies: [IXL-INV-03]
setup: {{lab: '{QUIET}'}}
steps:
  - fault: link st18-io cut
  - expect: ctc 18 signal 01 is G
    within: 2s
"""
MARKED = """\
import pytest

@pytest.mark.requirement("T1-CRC-01")
def test_marked() -> None:
    pass

@pytest.mark.requirement("TRAIN-ATO-01")
@pytest.mark.skip(reason="not here")
def test_skipped() -> None:
    pass
"""
CONFTEST = """\
from ktcs_bench.evidence.pytest_marks import mark_requirements

def pytest_collection_modifyitems(items):
    mark_requirements(items)
"""


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", *args],
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A procedures run (two shipped that pass, one that fails) and a pytest run, as written."""
    top = tmp_path_factory.mktemp("runs")
    must_fail = top / "must_fail.yaml"
    must_fail.write_text(MUST_FAIL, encoding="utf-8")
    (top / "proc").mkdir()
    run = cli(
        "test",
        "run",
        str(PROCEDURES / "route_set.yaml"),
        str(PROCEDURES / "route_conflict_refused.yaml"),
        str(must_fail),
        "--junit",
        str(top / "proc" / "junit.xml"),
        "--report",
        str(top / "proc" / "report"),
    )
    assert run.returncode == 1, run.stdout + run.stderr  # fmt: skip
    py = top / "py"
    py.mkdir()
    (py / "conftest.py").write_text(CONFTEST, encoding="utf-8")
    (py / "test_marked.py").write_text(MARKED, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(py),
         "-c", "/dev/null", f"--junitxml={top / 'pytest.xml'}", str(py)],
        capture_output=True, text=True, timeout=120, cwd=py,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    shutil.rmtree(py)  # only its JUnit is a result
    return top


def test_coverage_is_recorded_beside_the_results(runs: Path) -> None:
    beside = json.loads((runs / "proc" / "junit.coverage.json").read_text(encoding="utf-8"))
    folder = json.loads((runs / "proc" / "report" / "coverage.json").read_text(encoding="utf-8"))
    assert beside["stations"] == folder["stations"]
    st18 = beside["stations"]["18"]
    assert st18["routes"]["0111"]["set"] >= 1 and st18["routes"]["0111"]["cancelled"] >= 1
    assert st18["points"]["31"]["reverse"] >= 1  # route_conflict_refused throws it reverse
    assert st18["aspects"]["01"]["R"] >= 1 and st18["faults"]["link cut"] == 1
    assert sum(st18["codes"].values()) >= 2  # the approach's code stepped up and back
    assert set(beside["procedures"]) == {"route-set", "route-conflict-refused", "must-fail"}
    assert beside["procedures"]["route-set"]["stations"]["18"]["faults"]["link cut"] == 0


def test_the_matrix_lists_every_requirement_failing_first(runs: Path, tmp_path: Path) -> None:
    out = tmp_path / "trace"
    run = cli("trace", str(runs), "--out", str(out))
    assert run.returncode == 1, run.stderr  # must-fail's requirement has a failing check
    assert "FAILED    IXL-INV-03: must-fail" in run.stdout
    doc = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    catalogue = load_catalogue()
    status = {r["id"]: r["status"] for r in doc["requirements"]}
    assert list(status) == list(catalogue.requirements)
    assert status["IXL-INV-03"] == "failed"
    assert status["IXL-ROUTE-01"] == status["IXL-ROUTE-02"] == status["T1-CRC-01"] == "passed"
    assert status["TRAIN-ATO-01"] == "unchecked"  # its one check was skipped: no pass
    assert status["TRAIN-ATP-03"] == "unchecked"
    cov = doc["coverage"]
    assert cov["requirements"] == len(catalogue.requirements)
    assert cov["failed"] == 1 and cov["passed"] >= 9
    assert cov["checked"] == cov["passed"] + cov["failed"]
    route_set = next(r for r in doc["requirements"] if r["id"] == "IXL-ROUTE-01")["checks"]
    assert [(c["kind"], c["name"], c["verdict"]) for c in route_set] == [
        ("procedure", "route-set", "pass")
    ]
    page = route_set[0]["evidence"][0]
    assert page.endswith("route-set.html") and Path(page).is_file()
    pytest_check = next(r for r in doc["requirements"] if r["id"] == "T1-CRC-01")["checks"]
    assert pytest_check[0]["kind"] == "pytest" and pytest_check[0]["name"].endswith("test_marked")
    never = doc["operations"]
    assert set(never) == {"routes_never_set", "points_never_reversed", "aspects_never_shown",
                          "codes_never_sent", "faults_never_injected"}  # fmt: skip
    assert (
        "2192" in never["routes_never_set"]["18"] and "0111" not in never["routes_never_set"]["18"]
    )
    assert "0111" in never["routes_never_set"]["20"]
    assert "31" not in never["points_never_reversed"]["18"]
    assert "link cut" not in never["faults_never_injected"]["18"]
    rows = list(csv.DictReader((out / "trace.csv").open(encoding="utf-8")))
    assert rows[0]["id"] == "IXL-INV-03" and rows[0]["verdict"] == "fail"
    statuses = [r["status"] for r in rows]
    assert statuses.index("unchecked") < statuses.index("passed")
    page_html = (out / "index.html").read_text(encoding="utf-8")
    assert page_html.index("IXL-INV-03") < page_html.index("TRAIN-ATP-03") < page_html.index(
        "IXL-ROUTE-01")  # fmt: skip
    assert "<script" not in page_html and "routes never set" in page_html


def test_json_to_stdout_is_the_document_and_a_passing_run_exits_0(
    runs: Path, tmp_path: Path
) -> None:
    run = cli("trace", str(runs / "pytest.xml"), "--out", str(tmp_path / "t"), "--json")
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    assert doc == json.loads((tmp_path / "t" / "trace.json").read_text(encoding="utf-8"))
    assert doc["coverage"]["passed"] == 1 and doc["operations"] == {}


def test_lab_simulate_leaves_its_coverage_for_trace(tmp_path: Path) -> None:
    run = cli("lab", "simulate", "--for", "120", "--seed", "1", "--out", str(tmp_path / "sim"))
    assert run.returncode == 0, run.stderr
    cov = json.loads((tmp_path / "sim" / "coverage.json").read_text(encoding="utf-8"))
    assert cov["observed"] == ["aspects", "faults", "points", "routes"]  # its log has no codes
    assert cov["stations"]["18"]["routes"]["0111"]["set"] >= 1  # ARS set the first route
    done = cli("trace", str(tmp_path / "sim"), "--out", str(tmp_path / "t"), "--json")
    assert done.returncode == 0, done.stderr
    never = json.loads(done.stdout)["operations"]
    assert "codes_never_sent" not in never and "0111" not in never["routes_never_set"]["18"]


@pytest.mark.parametrize(
    ("write", "words"),
    [
        (None, "no such file or folder"),
        ("{}", "not a result the bench writes"),
        ("<testsuites><testcase", "not readable as JUnit XML or JSON"),
    ],
)
def test_a_bad_results_file_is_refused(tmp_path: Path, write: str | None, words: str) -> None:
    path = tmp_path / ("r.json" if write == "{}" else "r.xml")
    if write is not None:
        path.write_text(write, encoding="utf-8")
    run = cli("trace", str(path), "--out", str(tmp_path / "t"))
    assert run.returncode == 2 and words in run.stderr and "Traceback" not in run.stderr


def test_a_bad_catalogue_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "cat.yaml"
    bad.write_text("requirements:\n  - {id: A-1, text: t}\n", encoding="utf-8")
    run = cli("trace", str(tmp_path), "--catalogue", str(bad), "--out", str(tmp_path / "t"))
    assert run.returncode == 2 and "requirements[0].source: missing key" in run.stderr
