"""What the console takes from its pages, and what it answers "busy" (pure: the caller gives the
time, in seconds of a monotonic clock).

A page may ask faster than the CTC should carry out -- a script on the websocket sent 10,000 route
requests at once, and the console's work starved the lab sharing its loop until every station's
links dropped. The console is the lab's least important user, so its work is bounded:

* per page: at most `PAGE_RATE` requests a second (bursts of `PAGE_BURST`), and at most
  `DEPTH` waiting to go out, one at a time;
* per console: at most `CONSOLE_RATE` a second (`CONSOLE_BURST`) over all its pages;
* per station: at most `OUTSTANDING` controls awaiting their CONTROL_RESULT (the desk counts them,
  whoever sent them), far below the 128 frames a Type II sender keeps for a go-back.

A request beyond a bound is not queued and not sent: it is answered busy at once, with the bound
it met. `Gate.admit` decides at the door (rates, queue), `Gate.dispatch` as a request is about to
go out (the station's outstanding controls). Each page's busy answers are tallied, and
`Gate.report` says when the tally is due in the log: at the first refusal, then at most every
`REPORT_S` -- a flood gives a few log lines, not one per request.
"""

from __future__ import annotations

from dataclasses import dataclass, field

PAGE_RATE = 5.0  # requests a second from one page: an operator clicks two signals per route
PAGE_BURST = 10.0
CONSOLE_RATE = 20.0  # requests a second over every page of one console
CONSOLE_BURST = 40.0
DEPTH = 8  # requests of one page waiting to go out (it sends one at a time)
OUTSTANDING = 4  # controls awaiting their result at one station
REPORT_S = 5.0  # a page's busy answers are logged at most this often


@dataclass
class TokenBucket:
    """`rate` tokens a second, at most `burst` kept; it starts full."""

    rate: float
    burst: float
    tokens: float = field(init=False)
    at: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.tokens = self.burst

    def _fill(self, now: float) -> None:
        if self.at is not None and now > self.at:
            self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        if self.at is None or now > self.at:
            self.at = now

    def ready(self, now: float) -> bool:
        self._fill(now)
        return self.tokens >= 1.0

    def take(self, now: float) -> bool:
        """One token if there is one."""
        if not self.ready(now):
            return False
        self.tokens -= 1.0
        return True


@dataclass
class Page:
    """One page's share of the console: its bucket and its busy answers not yet logged."""

    bucket: TokenBucket
    busy: int = 0  # answered busy since the last report
    busy_total: int = 0
    why: str = ""  # the last bound met
    reported_at: float | None = None


@dataclass
class Gate:
    """The console's bounds (see the module docstring); one `Page` per websocket."""

    page_rate: float = PAGE_RATE
    page_burst: float = PAGE_BURST
    depth: int = DEPTH
    outstanding: int = OUTSTANDING
    report_s: float = REPORT_S
    bucket: TokenBucket = field(default_factory=lambda: TokenBucket(CONSOLE_RATE, CONSOLE_BURST))

    def page(self) -> Page:
        return Page(TokenBucket(self.page_rate, self.page_burst))

    def admit(self, page: Page, now: float, waiting: int) -> str | None:
        """A request from `page` arrives while `waiting` of its requests wait to go out: None if
        it may join them, else why it is answered busy."""
        if waiting >= self.depth:
            why = f"{waiting} requests of this page are waiting"
        elif not page.bucket.ready(now):
            why = f"more than {self.page_rate:g} requests a second from this page"
        elif not self.bucket.ready(now):
            why = f"more than {self.bucket.rate:g} requests a second at this console"
        else:
            page.bucket.take(now)
            self.bucket.take(now)
            return None
        return self.refused(page, why)

    def dispatch(self, page: Page, station: int, outstanding: int) -> str | None:
        """A request for `station` is about to go out while `outstanding` controls there await
        their result: None if it may, else why it is answered busy."""
        if outstanding < self.outstanding:
            return None
        return self.refused(page, f"{outstanding} controls to station {station} await their result")

    def refused(self, page: Page, why: str) -> str:
        page.busy += 1
        page.busy_total += 1
        page.why = why
        return why

    def report(self, page: Page, now: float, final: bool = False) -> int:
        """How many busy answers of `page` to log now (0: none due). Due at once after a quiet
        `report_s`, else once `report_s` has passed since the last report; `final`: the page is
        gone, whatever is left."""
        if page.busy == 0:
            return 0
        if not final and page.reported_at is not None and now - page.reported_at < self.report_s:
            return 0
        count, page.busy, page.reported_at = page.busy, 0, now
        return count
