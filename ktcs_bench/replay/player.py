"""A replay: the frames of one direction of a capture sent into a target, paced as asked, every
reply taken as it comes; then the replies compared with an expected capture.

`Replay.run()` is what `ktcs-bench replay` does, as a library call: it sends, paces and collects;
the caller sees each frame sent and each reply through `on_sent` / `on_reply` (to print or record
them). Pacing: "original" keeps the capture's gaps (at least; `max_gap` caps them), "line" the line
rate at `pace` bit/s (10 bits a byte; None: no pacing), "step" waits for a reply -- or for `step_go()`
to say go (an operator's Enter) -- before each next frame.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ktcs_bench.capture import Capture, CaptureRecord, reverse_direction
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.codec.vote import choose_profile
from ktcs_bench.errors import PeerError
from ktcs_bench.replay.targets import ReplayTarget

QUIET_CAP = 10  # at the end, wait at most this many `wait` periods while replies keep coming
TIMINGS = ("original", "line", "step")


def capture_profile(
    capture: Capture, named: str | None, header_profile: str | None, protocol: str
) -> FrameProfile:
    """The profile to replay `capture` with: the one named, else the target's (a tap's header),
    else the capture's own, else the shipped one of `protocol` ("auto": any) its frames check
    with most often."""
    for name in (named, header_profile, capture.profile):
        if name:
            return get_profile(name)
    data = b"".join(r.data for r in capture.records)
    return choose_profile(data, protocol)[0]


def frames_of(records: list[CaptureRecord], profile: FrameProfile) -> list[bytes]:
    """Each record split into frames (and garbage spans), as raw bytes, in order."""
    out: list[bytes] = []
    for r in records:
        dec = StreamDecoder(profile)
        out += [x.raw for x in dec.feed(r.data) + dec.close()]
    return out


def expected_replies(capture: Capture, send_dirs: tuple[str, ...]) -> list[CaptureRecord]:
    """The replies in an expected capture: its frames in the reverse of a sent direction, else
    every frame not in a sent direction (a capture of the replies alone)."""
    reverse = {reverse_direction(d) for d in send_dirs}
    if reverse & set(capture.directions):
        return [r for r in capture.records if r.direction in reverse]
    return [r for r in capture.records if r.direction not in send_dirs]


def first_difference(expected: list[bytes], got: list[bytes]) -> str | None:
    for k in range(max(len(expected), len(got))):
        e = expected[k] if k < len(expected) else None
        g = got[k] if k < len(got) else None
        if e == g:
            continue
        if e is None:
            assert g is not None
            return f"reply frame {k + 1}: not expected (the expected capture has {len(expected)}); got {g.hex(' ').upper()}"
        if g is None:
            return f"reply frame {k + 1}: missing (got {len(got)} replies); expected {e.hex(' ').upper()}"
        return (
            f"reply frame {k + 1} differs:\n  expected {e.hex(' ').upper()}\n"
            f"  got      {g.hex(' ').upper()}"
        )
    return None


@dataclass
class Replay:
    """One replay of `to_send` into `target`; `run()` returns the replies, in order."""

    target: ReplayTarget
    to_send: list[CaptureRecord]
    out_dir: str  # the direction the frames sent are recorded with
    timing: str = "line"
    max_gap: float | None = None  # "original": cap every silence at this many seconds
    pace: int | None = 9600  # "line": bit/s (None: as fast as the target takes them)
    wait: float = 1.0  # quiet that ends the replay; "step" off a terminal: how long to wait
    on_sent: Callable[[CaptureRecord], None] = lambda rec: None
    on_reply: Callable[[CaptureRecord], None] = lambda rec: None
    step_go: Callable[[], bool] | None = None  # "step" on a terminal: True once told to go on
    name: str = "the target"  # how an error of the target's is introduced
    replies: list[CaptureRecord] = field(default_factory=list)

    def _take_until(self, until: float) -> int:
        """Take replies until the monotonic time `until`; how many came."""
        got = 0
        while True:
            left = until - time.monotonic()
            try:
                rec = self.target.replies.get(timeout=max(0.0, min(left, 0.05)))
            except queue.Empty:
                if left <= 0:
                    return got
                continue
            self.replies.append(rec)
            self.on_reply(rec)
            got += 1

    def run(self) -> list[CaptureRecord]:
        pump = self._take_until
        start = time.monotonic()
        line_free = start
        last_time = self.to_send[0].time  # "original": each frame follows the one before
        last_sent = start  # by the capture's gap (capped at max_gap), never less
        for k, rec in enumerate(self.to_send):
            if self.timing == "original" and rec.time is not None and last_time is not None:
                gap = max(0.0, rec.time - last_time)
                pump(last_sent + (gap if self.max_gap is None else min(gap, self.max_gap)))
                last_time = rec.time
            elif self.timing == "line":
                pump(line_free)
            elif self.timing == "step" and k > 0:
                wait_until = None if self.step_go is not None else time.monotonic() + self.wait
                while not pump(time.monotonic() + 0.05) and not (
                    self.step_go is not None and self.step_go()
                ):
                    if wait_until is not None and time.monotonic() >= wait_until:
                        break
            if self.target.errors:
                raise PeerError(f"{self.name}: {self.target.errors[0]}")
            self.target.send(rec.data)
            last_sent = time.monotonic()
            self.on_sent(CaptureRecord(time.time(), self.out_dir, rec.data))
            if self.pace:
                line_free = max(line_free, time.monotonic()) + len(rec.data) * 10 / self.pace
        for _ in range(QUIET_CAP):
            if not pump(time.monotonic() + self.wait):
                break
        return self.replies


def compare(
    expect: Capture, send_dirs: tuple[str, ...], replies: list[CaptureRecord], profile: FrameProfile
) -> tuple[int, str | None]:
    """The replies against an expected capture, frame by frame: (frames got, the first
    difference or None)."""
    want = frames_of(expected_replies(expect, send_dirs), profile)
    got = frames_of(replies, profile)
    return len(got), first_difference(want, got)
