"""pytest runs procedure files (`procedure.pytest_plugin`): every shipped procedure collected as
an item, tags as marks, requirement ids as JUnit properties, a failed step the failure's words,
a file `test run` would refuse a collection error. Real pytest runs in subprocesses, real labs in
one process on the virtual clock."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from ktcs_bench.datafiles import data_dir

PROCEDURES = data_dir("emulators") / "procedures"
QUIET = PROCEDURES / "labs" / "quiet.yaml"
PLUGIN = "ktcs_bench.procedure.pytest_plugin"
MUST_FAIL = f"""\
id: must-fail
title: expects a signal to clear with no route set
verifies: [IXL-INV-03]
tags: [negative-check]
setup: {{lab: '{QUIET}'}}
steps:
  - expect: ctc 18 signal 01 is G
    within: 2s
    note: nothing set it
"""


def pytest_run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-p", PLUGIN, "-p", "no:cacheprovider", "--rootdir",
         str(cwd), "-c", "/dev/null", *args],
        capture_output=True, text=True, timeout=600, cwd=cwd,
    )  # fmt: skip


def test_every_shipped_procedure_is_collected(tmp_path: Path) -> None:
    run = pytest_run("--collect-only", "-q", str(PROCEDURES), cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    shipped = sorted(PROCEDURES.glob("*.yaml"))
    assert f"{len(shipped)} tests collected" in run.stdout
    for path in shipped:
        assert f"{path.name}::" in run.stdout, path  # its labs (labs/*.yaml) are not items
    items = [line for line in run.stdout.splitlines() if "::" in line]
    assert [i.split("::")[1] for i in items[:2]] == ["meet-at-20", "train-run-18-22"]  # longest
    only = pytest_run("--collect-only", "-q", "-m", "approach_locking", str(PROCEDURES),
                      cwd=tmp_path)  # fmt: skip
    assert "cancel_approach_locked.yaml::cancel-approach-locked" in only.stdout
    assert "1/18 tests collected" in only.stdout.replace(" (17 deselected)", "")


def test_procedures_run_as_items_with_requirements_and_the_failed_step(tmp_path: Path) -> None:
    folder = tmp_path / "procedures"
    folder.mkdir()
    (folder / "must_fail.yaml").write_text(MUST_FAIL, encoding="utf-8")
    junit = tmp_path / "j.xml"
    run = pytest_run(str(PROCEDURES / "route_set.yaml"), str(folder), f"--junitxml={junit}",
                     cwd=tmp_path)  # fmt: skip
    assert run.returncode == 1, run.stdout + run.stderr
    assert "1 failed, 1 passed" in run.stdout
    assert "step 1" in run.stdout and "ctc 18 signal 01 is G" in run.stdout
    cases = {tc.get("name"): tc for tc in ET.parse(junit).getroot().iter("testcase")}
    assert set(cases) == {"route-set", "must-fail"}
    props = [(p.get("name"), p.get("value")) for p in cases["route-set"].iter("property")]
    assert ("requirement", "IXL-ROUTE-01") in props
    assert cases["must-fail"].find("failure") is not None
    assert cases["route-set"].find("failure") is None


def test_a_procedure_runs_beside_labgrids_pytest_plugin(tmp_path: Path) -> None:
    """labgrid (the test extra installs it) registers a pytest plugin that reads every item's
    fixture names; outside this project's own configuration (`-p no:labgrid`) it is loaded, as it
    is here (`-c /dev/null`)."""
    run = pytest_run(str(PROCEDURES / "route_set.yaml"), cwd=tmp_path)
    assert "labgrid" in next(
        line for line in run.stdout.splitlines() if line.startswith("plugins:")
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 passed" in run.stdout


def test_a_procedure_naming_an_unknown_requirement_is_a_collection_error(tmp_path: Path) -> None:
    folder = tmp_path / "procedures"
    folder.mkdir()
    (folder / "p.yaml").write_text(MUST_FAIL.replace("IXL-INV-03", "IXL-INV-77"), encoding="utf-8")
    run = pytest_run(str(folder), cwd=tmp_path)
    assert run.returncode == 2, run.stdout + run.stderr  # pytest: errors during collection
    assert "verifies[0]: 'IXL-INV-77' is not a requirement" in run.stdout


FIXTURE_TEST = f"""\
from ktcs_bench import messages as msg


def test_a_route_through_the_lab_access(ktcs_lab) -> None:
    async def check(access):
        for _ in range(120):  # up to 60 s of lab time for the CTC to see station 18 synced
            s = (await access.device("ctc", msg.Status()))["status"]["stations"]["18"]
            if s["link"] == "up" and s["synced"]:
                break
            await access.sleep(0.5)
        answer = await access.device("ctc", msg.Route(station=18, entry="01", exit="11"))
        assert answer["ok"], answer
        for _ in range(60):
            await access.sleep(0.5)
            routes = (await access.device("ixl18", msg.Status()))["status"]["routes"]
            if "0111" in routes:
                return access.now()
        raise AssertionError(f"route 0111 not set: {{routes}}")

    assert ktcs_lab.run(check, "{QUIET}") > 0
"""


def test_a_python_test_reaches_a_lab_with_the_ktcs_lab_fixture(tmp_path: Path) -> None:
    (tmp_path / "test_lab.py").write_text(FIXTURE_TEST, encoding="utf-8")
    run = pytest_run("-q", str(tmp_path / "test_lab.py"), cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 passed" in run.stdout
