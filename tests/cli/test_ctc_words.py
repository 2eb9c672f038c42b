"""`ktcs-bench ctc` says things as an operator does (issue 13 item 9): the command log in the words
the operator typed, and `show` marks what the CTC no longer knows (link down) as unknown instead of
the last indications. A real lab, operated through the real command."""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest

from tests.lab.conftest import RunningLab, start_lab, wait_until

LAB = "wordslab"
STAMP = r"\d\d:\d\d:\d\d"


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    with start_lab(tmp_path_factory.mktemp(LAB), LAB, clear=False) as running:
        yield running


def ctc(lab: RunningLab, *words: str) -> str:
    result = lab.cli("ctc", "--lab", LAB, "--no-colour", *words)
    assert result.returncode in (0, 1), result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    return result.stdout


def test_ctc_log_is_in_the_operator_words_of_each_command_and_its_result(lab: RunningLab) -> None:
    assert "-> accepted" in ctc(lab, "route", "set", "18", "S1", "S11")
    assert "not in this lab" in ctc(lab, "point", "reverse", "99", "31")
    ctc(lab, "signal", "stop", "20", "01")
    log = ctc(lab, "log")
    assert "{" not in log and "'cmd'" not in log, log  # not a Python dict
    lines = log.splitlines()
    for wanted in (
        rf"{STAMP} route set 18 01 11 -> accepted",
        rf"{STAMP} point reverse 99 31 -> refused by the CTC: station 99 is not in this lab",
        rf"{STAMP} signal stop 20 01 -> (accepted|rejected: .+)",
    ):
        assert any(re.fullmatch(wanted + ".*", ln) for ln in lines), (wanted, log)


def test_ctc_show_marks_what_it_no_longer_knows_as_unknown(lab: RunningLab) -> None:
    before = ctc(lab, "show", "22")
    assert "link up" in before and "unknown" not in before, before
    aspects = re.search(r"signals  (.*)", before)
    assert aspects and re.search(r"\b01:R\b", aspects.group(1)), before  # a known aspect
    assert lab.lab({"cmd": "kill", "device": "ixl22"})["ok"]
    down = wait_until(
        "the CTC sees station 22's link down",
        lambda: "link down" in (text := ctc(lab, "show", "22")) and text,
        timeout=60,
    )
    lines = dict(ln.strip().split(None, 1) for ln in down.splitlines()[1:])
    assert "unknown mode" in down.splitlines()[0], down
    assert lines["routes"] == "unknown" and lines["occupied"] == "unknown", down
    for field in ("points", "signals"):
        shown = dict(item.split(":", 1) for item in lines[field].split())
        assert shown and set(shown.values()) == {"unknown"}, (field, down)
    # `ctc status` says the same of station 22, and still knows the stations whose links are up
    status = ctc(lab, "status")
    assert "station 22: unknown mode, link down" in status, status
    assert "station 18: center mode, link up" in status, status
    # once the IXL is back and has sent its full state, the CTC knows again
    assert lab.lab({"cmd": "restart", "device": "ixl22"})["ok"]
    wait_until(
        "station 22 known again",
        lambda: "unknown" not in (text := ctc(lab, "show", "22")) and "link up" in text,
        timeout=60,
    )


def test_the_lab_status_says_unknown_too(lab: RunningLab) -> None:
    """`lab status` draws the same summary: a station the CTC cannot see has no routes listed as
    '-' (none), but 'unknown'."""
    assert lab.lab({"cmd": "kill", "device": "ixl20"})["ok"]
    try:
        text = wait_until(
            "lab status shows station 20 unknown",
            lambda: "routes unknown" in (
                out := lab.cli("lab", "status", LAB, "--no-colour").stdout
            ) and out,
            timeout=60,
        )  # fmt: skip
        block = text.split("st20", 1)[1].split("\nst22", 1)[0]
        assert "routes unknown" in block and "occupied unknown" in block, text
    finally:
        assert lab.lab({"cmd": "restart", "device": "ixl20"})["ok"]
