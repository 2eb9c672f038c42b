"""A device's conformance statement (ICS): the suite runs against the real ATC emulator the
cases that apply and reports the ones the statement rules out as not applicable -- in text,
JSON and JUnit (skipped, with the reason) -- never as passed; every shipped statement reads clean,
and a bad one is refused before anything runs."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest

from ktcs_bench.conformance.ics import load_ics
from ktcs_bench.conformance.type1_cases import TYPE1_CASES
from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from tests.conformance.conftest import Proc, cli

ICS = data_dir("emulators") / "ics"
NO_LINK_TEST = """\
role: atc
device: an ATC without a link test nor REQUEST_ALL
link_test: false
opcodes: [ALL_INFO, CHANGE, ACK, NAK]
timings: {link_test_period: 1.0, retry_count: 3}
"""


@pytest.fixture
def atc(tmp_path: Path) -> Iterator[str]:
    proc = Proc(["emulator", "atc", "--station", "18", "--link", "ixl=pty", "--unpaced"],
                tmp_path / "atc.log")  # fmt: skip
    try:
        yield str(proc.wait_ready()["ptys"]["ixl"])
    finally:
        proc.stop()


def test_every_shipped_statement_reads_clean() -> None:
    found = {p.stem: load_ics(p) for p in sorted(ICS.glob("*.yaml"))}
    assert {i.role for i in found.values()} == {"atc", "trackside", "ixl", "ctc"}
    assert all(i.link_test for i in found.values())


def test_cases_the_statement_rules_out_are_not_applicable_never_passed(
    atc: str, tmp_path: Path
) -> None:
    ics = tmp_path / "ics.yaml"
    ics.write_text(NO_LINK_TEST, encoding="utf-8")
    junit = tmp_path / "j.xml"
    run = cli("--no-colour", "conformance", "--ics", str(ics), "--target", atc, "--station", "18",
              "--unpaced", "--junit", str(junit), "--json", timeout=180)  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    cases = {c["name"]: c for c in json.loads(run.stdout)["cases"]}
    na = {n for n, c in cases.items() if c["verdict"] == "not applicable"}
    assert na == {"link-test-timing", "request-all"}
    assert cases["request-all"]["message"].startswith("not applicable: the device does not "
                                                      "support REQUEST_ALL")  # fmt: skip
    assert all(c["verdict"] == "pass" for n, c in cases.items() if n not in na)
    assert set(cases) == {c.name for c in TYPE1_CASES}
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("skipped") == "2" and suite.get("failures") == "0"
    skipped = {tc.get("name"): tc.find("skipped") for tc in suite.iter("testcase")}
    lt = skipped["link-test-timing"]
    assert lt is not None and "not applicable: the device sends no link test" in str(
        lt.get("message")
    )
    text = cli("--no-colour", "conformance", "--ics", str(ics), "--target", atc, "--station",
               "18", "--unpaced", "--case", "link-test-timing", "--case", "framing", timeout=120)  # fmt: skip
    assert text.returncode == 0, text.stdout + text.stderr
    assert "N/A   link-test-timing" in text.stdout and "1 pass, 1 not applicable" in text.stdout


@pytest.mark.parametrize(
    ("body", "place", "words"),
    [
        ("role: signalman\n", "role", "'signalman' is not a role"),
        ("role: atc\nopcodes: [ALL_INFO, TELEPORT]\n", "opcodes[1]", "'TELEPORT' is no opcode"),
        ("role: atc\nmax_frame: 5000\n", "max_frame", "5000 DATA bytes: more than"),
        ("role: atc\ntimings: {delta_r: -1}\n", "timings.delta_r", "must be greater than 0"),
        ("role: atc\nlink_tests: no\n", "link_tests", "unknown key"),
    ],
)
def test_a_bad_statement_is_one_message_naming_the_place(
    tmp_path: Path, body: str, place: str, words: str
) -> None:
    path = tmp_path / "ics.yaml"
    path.write_text(body, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_ics(path)
    assert err.value.place == place and words in err.value.problem, str(err.value)


def test_a_statement_of_another_role_is_refused(tmp_path: Path) -> None:
    run = cli("conformance", "--ics", str(ICS / "atc.yaml"), "--role", "ctc", "--target",
              "tcp://127.0.0.1:9")  # fmt: skip
    assert run.returncode == 2 and "is for role atc" in run.stderr
