"""The requirements catalogue: the shipped one reads clean and holds every id a check names; a
bad catalogue is one message naming file, key path and line; a procedure, a Python test or a
catalogue of one's own naming an id the catalogue lacks is refused before anything runs."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ktcs_bench.conformance.type1_cases import TYPE1_CASES
from ktcs_bench.conformance.type2_cases import TYPE2_CASES
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.evidence.catalogue import load_catalogue
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.threats import THREATS
from ktcs_bench.threats.report import REQUIREMENTS

PROCEDURES = data_dir("emulators") / "procedures"
GOOD = """\
catalogue: mine
requirements:
  - id: MY-DEV-01
    text: My device answers.
    source: my spec §1
    roles: [atc]
"""


def test_the_shipped_catalogue_covers_the_areas_the_spec_names() -> None:
    cat = load_catalogue()
    assert len(cat.requirements) >= 60
    prefixes = {rid.split("-")[0] for rid in cat.requirements}
    assert {"T1", "T2", "IXL", "DIR", "TS", "ATC", "TRAIN", "SYS", "EN50159"} <= prefixes
    assert all(r.text and r.source and r.roles for r in cat.requirements.values())


def test_every_conformance_case_and_threat_names_catalogue_ids() -> None:
    cat = load_catalogue()
    for case in (*TYPE1_CASES, *TYPE2_CASES):
        assert case.verifies, case.name
        assert not cat.unknown(case.verifies), case.name
    assert set(REQUIREMENTS) == set(THREATS)
    for threat, ids in REQUIREMENTS.items():
        assert ids and not cat.unknown(ids), threat


def test_every_shipped_procedure_verifies_catalogue_ids() -> None:
    cat = load_catalogue()
    for path in sorted(PROCEDURES.glob("*.yaml")):
        proc = load_procedure(path)
        assert proc.verifies and not cat.unknown(proc.verifies), path


BAD = [
    # (the requirements list, the key path named, words of the problem)
    ("  - {id: A-1, text: t, source: s}\n  - {id: A-1, text: u, source: s}\n",
     "requirements[1].id", "A-1 given twice"),
    ("  - {id: ixl route 3, text: t, source: s}\n", "requirements[0].id", "'ixl route 3' is no id"),
    ("  - {id: A-1, text: t, source: s, roles: [signalman]}\n", "requirements[0].roles[0]",
     "'signalman' is no device kind"),
    ("  - {id: A-1, source: s}\n", "requirements[0].text", "missing key"),
    ("  - {id: A-1, text: '', source: s}\n", "requirements[0].text", "must not be empty"),
    ("  - {id: A-1, text: t, source: s, owner: me}\n", "requirements[0].owner", "unknown key"),
    ("  - {id: 7, text: t, source: s}\n", "requirements[0].id", "must be a string"),
    ("  []\n", "requirements", "must not be empty"),
]  # fmt: skip


@pytest.mark.parametrize(("body", "place", "problem"), BAD)
def test_a_bad_catalogue_is_one_message_naming_the_place(
    tmp_path: Path, body: str, place: str, problem: str
) -> None:
    path = tmp_path / "cat.yaml"
    path.write_text("requirements:\n" + body, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_catalogue(path)
    assert err.value.file == str(path)
    assert err.value.place == place, str(err.value)
    assert err.value.problem.startswith(problem), str(err.value)


def test_a_duplicate_id_names_its_line(tmp_path: Path) -> None:
    path = tmp_path / "cat.yaml"
    path.write_text(GOOD + "  - id: MY-DEV-01\n    text: again\n    source: s\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"MY-DEV-01 given twice \(line 7\)"):
        load_catalogue(path)


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", *args],
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def procedure(tmp_path: Path, verifies: str) -> Path:
    path = tmp_path / "p.yaml"
    path.write_text(f"id: p\ntitle: t\nverifies: {verifies}\nsetup: {{lab: reference}}\n"
                    "steps:\n  - wait: 1s\n", encoding="utf-8")  # fmt: skip
    return path


def test_an_unknown_requirement_is_refused_before_anything_runs(tmp_path: Path) -> None:
    path = procedure(tmp_path, "[IXL-ROUTE-01, IXL-ROUTE-99]")
    run = cli("test", "run", str(path), "--junit", str(tmp_path / "j.xml"))
    assert run.returncode == 2, run.stderr
    assert f"{path}: verifies[1]: 'IXL-ROUTE-99' is not a requirement" in run.stderr
    assert "(line 3)" in run.stderr and "Traceback" not in run.stderr
    assert not (tmp_path / "j.xml").exists()  # refused before anything ran


def test_a_catalogue_of_ones_own_decides_what_is_known(tmp_path: Path) -> None:
    mine = tmp_path / "mine.yaml"
    mine.write_text(GOOD, encoding="utf-8")
    path = procedure(tmp_path, "MY-DEV-01")
    assert load_procedure(path, load_catalogue(mine)).verifies == ("MY-DEV-01",)
    with pytest.raises(ConfigError, match="'MY-DEV-01' is not a requirement"):
        load_procedure(path)  # the shipped catalogue has no MY-DEV-01
    run = cli("test", "run", str(procedure(tmp_path, "IXL-ROUTE-01")), "--catalogue", str(mine))
    assert run.returncode == 2 and "'IXL-ROUTE-01' is not a requirement" in run.stderr
    bad = cli("test", "run", str(path), "--catalogue", str(tmp_path / "none.yaml"))
    assert bad.returncode == 2 and "none.yaml" in bad.stderr and "Traceback" not in bad.stderr


MARKED = """\
import pytest

@pytest.mark.requirement({ids})
def test_it() -> None:
    pass
"""
CONFTEST = """\
from ktcs_bench.evidence.pytest_marks import mark_requirements

def pytest_collection_modifyitems(items):
    mark_requirements(items)
"""


def run_pytest(tmp_path: Path, ids: str) -> subprocess.CompletedProcess[str]:
    (tmp_path / "conftest.py").write_text(CONFTEST, encoding="utf-8")
    (tmp_path / "test_marked.py").write_text(MARKED.format(ids=ids), encoding="utf-8")
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir",
         str(tmp_path), "-c", "/dev/null", f"--junitxml={tmp_path / 'j.xml'}", str(tmp_path)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip


def test_a_marked_python_test_gives_junit_its_requirements(tmp_path: Path) -> None:
    run = run_pytest(tmp_path, '"T1-CRC-01", "T1-CRC-02"')
    assert run.returncode == 0, run.stdout + run.stderr
    case = ET.parse(tmp_path / "j.xml").getroot().find(".//testcase")
    assert case is not None
    props = [(p.get("name"), p.get("value")) for p in case.iter("property")]
    assert props == [("requirement", "T1-CRC-01"), ("requirement", "T1-CRC-02")]


def test_a_python_test_naming_an_unknown_requirement_stops_the_run(tmp_path: Path) -> None:
    run = run_pytest(tmp_path, '"T1-CRC-77"')
    assert run.returncode == 4, run.stdout + run.stderr  # pytest's usage error
    assert "test_marked.py::test_it" in run.stderr and "'T1-CRC-77'" in run.stderr
