"""The console's page asks for an interval's traffic permission (SPEC §6.6): a `direction`
request -- what a click on an interval's arrow sends -- reaches the CTC as `ctc direction ST
INTERVAL` does (DRC{interval}=1 to that station's interlocking) and is answered with what came
of it; an interval the station does not border, or one at the lab's edge, is refused by the CTC
with its reason, nothing sent. A real websocket client (aiohttp) against the running bench."""

from __future__ import annotations

import asyncio
import re
from typing import Any

from playwright.sync_api import expect

from .conftest import Bench
from .test_origin import operate, ws_url


def ask(bench: Bench, station: int, interval: str) -> dict[str, object]:
    request = {"type": "direction", "station": station, "interval": interval}
    result = asyncio.run(operate(ws_url(bench.console), None, request))
    assert isinstance(result, dict), result
    return result


def test_a_direction_request_asks_the_interlocking_for_the_permission(bench: Bench) -> None:
    before = len(bench.console.log_entries)
    result = ask(bench, 20, "1820")
    assert str(result["text"]).startswith(
        "station 20: ask for the permission of interval 1820: "
    ), result
    said = [e["text"] for e in list(bench.console.log_entries)[before:]]
    assert "station 20: ask for the permission of interval 1820 (DRC1820=1) sent" in said, said


def test_a_direction_request_the_ctc_cannot_carry_out_is_refused_with_its_reason(
    bench: Bench,
) -> None:
    before = len(bench.console.log_entries)
    edge = ask(bench, 22, "2224")
    assert edge["ok"] is False and "at the lab's edge" in str(edge["text"]), edge
    elsewhere = ask(bench, 18, "2022")
    assert elsewhere["ok"] is False and "no interval 2022 here" in str(elsewhere["text"]), elsewhere
    said = [e["text"] for e in list(bench.console.log_entries)[before:]]
    assert not any(x.endswith(" sent") for x in said), said


def test_a_click_on_an_interval_arrow_asks_at_the_end_that_does_not_hold_it(page: Any) -> None:
    """In headless Chromium: 1820 is held by 18 (the rigs start so), so a click on its arrow
    asks at 20 and the CTC's answer is shown; 2224 lies at the lab's edge, and the CTC says
    there is no neighbour to ask."""
    page.locator("#iv-1820 .iv-head.up").click()  # its arrow: up, held by 18
    expect(page.locator("#result")).to_have_text(
        re.compile(r"^station 20: ask for the permission of interval 1820: (accepted|rejected)")
    )
    page.locator("#iv-2224 .iv-head.down").click()
    expect(page.locator("#result")).to_have_text(re.compile(r"interval 2224 is at the lab's edge"))
