"""Issue 8 against the real lab: the console the CTC process serves in `lab up` (every device its
own process, Type I on paced ptys), driven by clicks in headless Chromium."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.console.conftest import ARTIFACTS

from .conftest import RunningLab, start_lab, wait_until


@pytest.fixture(scope="module")
def console_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    with start_lab(tmp_path_factory.mktemp("consolelab"), "consolelab") as lab:
        yield lab


def test_route_set_by_clicks_in_the_lab_console(
    browser_context: Any, console_lab: RunningLab
) -> None:
    lab = console_lab
    url = lab.state()["devices"]["ctc"]["console"]
    page = browser_context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        page.goto(url)
        page.wait_for_selector("#conn.up")
        page.locator("#sig-20-01").click()
        page.locator("#sig-20-11").click()
        expect(page.locator("#result")).to_have_text(
            "station 20: set route 01-11: accepted", timeout=20_000
        )
        # the route really set in the IXL process, seen at the CTC
        wait_until(
            "route 0111 at station 20",
            lambda: "0111" in lab.ctc({"cmd": "show", "station": 20})["summary"]["routes"],
        )
        expect(page.locator('#diagram line.tc[data-tc="TC2053A"]').first).to_have_class(
            re.compile(r"\blocked\b"), timeout=20_000
        )
        expect(page.locator("#sig-20-01")).to_have_attribute(
            "data-aspect", re.compile(r"^(Y|YG|G)$"), timeout=20_000
        )
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        shot = ARTIFACTS / "lab_route_set.png"
        page.screenshot(path=str(shot), full_page=True)
        print(f"\nlab console screenshot: {shot}")
    finally:
        page.close()
    assert not errors, f"JavaScript errors on the page: {errors}"
