"""The console's gate (pure): which requests a page may make, and when busy answers are logged."""

from __future__ import annotations

from ktcs_bench.console.gate import Gate, TokenBucket


def test_a_page_gets_its_burst_then_its_rate() -> None:
    gate = Gate(page_rate=5.0, page_burst=10.0)
    page = gate.page()
    admitted = [gate.admit(page, 0.0, 0) is None for _ in range(30)]
    assert admitted.count(True) == 10  # the burst, at one instant
    assert gate.admit(page, 0.1, 0) is not None  # then 5 a second: one each 0.2 s
    assert gate.admit(page, 0.2, 0) is None
    assert gate.admit(page, 0.2, 0) is not None
    assert page.busy_total == 22
    assert "requests a second from this page" in page.why


def test_the_console_bounds_all_its_pages_together() -> None:
    gate = Gate(page_rate=100.0, page_burst=100.0, bucket=TokenBucket(20.0, 40.0))
    pages = [gate.page() for _ in range(10)]
    admitted = sum(gate.admit(p, 0.0, 0) is None for p in pages for _ in range(10))
    assert admitted == 40
    assert "at this console" in pages[-1].why


def test_a_page_with_its_queue_full_is_answered_busy_whatever_its_rate() -> None:
    gate = Gate(depth=8)
    page = gate.page()
    assert gate.admit(page, 0.0, 7) is None
    assert gate.admit(page, 0.0, 8) == "8 requests of this page are waiting"


def test_a_station_with_its_controls_outstanding_is_busy() -> None:
    gate = Gate(outstanding=4)
    page = gate.page()
    assert gate.dispatch(page, 18, 3) is None
    assert gate.dispatch(page, 18, 4) == "4 controls to station 18 await their result"


def test_busy_answers_are_logged_at_once_then_at_most_every_report_s() -> None:
    gate = Gate(page_burst=1.0, report_s=5.0)
    page = gate.page()
    gate.admit(page, 0.0, 0)
    gate.admit(page, 0.0, 0)
    assert gate.report(page, 0.0) == 1  # the first, at once
    for t in range(100):
        gate.admit(page, 0.01 * t, 8)
    assert gate.report(page, 1.0) == 0  # within report_s of the last report
    assert gate.report(page, 5.0) == 100
    assert gate.report(page, 11.0) == 0  # nothing new
    gate.admit(page, 12.0, 8)
    assert gate.report(page, 12.0) == 1  # a quiet page's first, at once again
    gate.admit(page, 12.5, 8)
    assert gate.report(page, 13.0, final=True) == 1  # the page is gone: what is left
