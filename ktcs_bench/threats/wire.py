"""A running tap seen from outside, as the threat campaign uses it: its control port to inject,
its subscribe stream to read what crossed the wire.

The stream carries the tap's records and its own events (fault, send, connection) in the order the
tap saw them, so "what came after this injection" is exact: `act()` returns the position of the
injection's own event in the stream, not a guess from a clock.
"""

from __future__ import annotations

import bisect
import threading
import time
from collections.abc import Callable, Iterator

from ktcs_bench.codec import Frame, StreamDecoder, get_profile
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.core import TapEvent
from ktcs_bench.tap.runner import TapStatus

STREAM_LIMIT = 200_000  # events kept; a campaign reads a few thousand


def wait_for(pred: Callable[[], bool], timeout: float, step: float = 0.05) -> bool:
    """Poll `pred` until it holds or `timeout` seconds pass; its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()


class WireTap:
    """`WireTap("st18-atc")`: a tap by name, or by its control address (HOST, PORT)."""

    def __init__(self, tap: str | tuple[str, int]) -> None:
        self._control = TapClient(tap)
        self.address = self._control.address
        try:
            self.info: TapStatus = self._control.status()
            self._feed = TapClient(self.address)
        except BaseException:
            self._control.close()
            raise
        self._thread: threading.Thread | None = None
        host, port = self.address
        try:
            stream = self._feed.subscribe(history=True)
            header = next(stream)
            self.name = str(header.get("tap") or f"{host}:{port}")
            self.kind = str(header.get("kind", "tap"))
            names = header.get("names")
            if not (isinstance(names, list) and len(names) == 2 and "profile" in header):
                raise PeerError(f"{host}:{port} answered like a tap but without its ends/profile")
            self.names: tuple[str, str] = (str(names[0]), str(names[1]))
            self.profile: FrameProfile = get_profile(str(header["profile"]))
        except UsageError as exc:
            self.close()
            raise UsageError(
                f"tap {host}:{port}: its frame profile is unknown here ({exc})"
            ) from None
        except BaseException:
            self.close()
            raise
        self._events: list[TapEvent] = []
        self._frames: list[tuple[int, str, Frame]] = []  # (stream position, direction, frame)
        self._decoders: dict[str, StreamDecoder] = {}
        self._lock = threading.Lock()
        self._thread = threading.Thread(
            target=self._read, args=(stream,), name=f"wiretap-{self.name}", daemon=True
        )
        self._thread.start()

    @property
    def protocol(self) -> str:
        return self.profile.protocol

    def _read(self, stream: Iterator[TapEvent]) -> None:
        try:
            for event in stream:
                with self._lock:
                    self._events.append(event)
                    if "hex" in event and "direction" in event:
                        self._decode(len(self._events) - 1, str(event["direction"]), event["hex"])
                    if len(self._events) > STREAM_LIMIT:
                        raise PeerError("the tap's stream outgrew the campaign's buffer")
        except (PeerError, ValueError):
            pass  # the tap went away: the campaign sees no more traffic and says so

    def _decode(self, position: int, direction: str, text: str) -> None:
        """One decoder a direction, so a frame split over two records is still one frame."""
        try:
            data = bytes.fromhex(text)
        except ValueError:
            return
        decoder = self._decoders.setdefault(direction, StreamDecoder(self.profile))
        for f in decoder.feed(data):
            if isinstance(f, Frame):
                self._frames.append((position, direction, f))

    def close(self) -> None:
        self._control.close()
        feed = getattr(self, "_feed", None)
        if feed is not None:
            feed.close()
        if getattr(self, "_thread", None) is not None:
            assert self._thread is not None
            self._thread.join(timeout=5)

    def __enter__(self) -> WireTap:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commands --------------------------------------------------------------------------------
    def mark(self) -> int:
        with self._lock:
            return len(self._events)

    def act(self, command: str, timeout: float = 5.0) -> int:
        """Send a control command that changes the wire (a fault, `send`, `clear`, `restore`);
        the stream position of its event (what follows happened after it)."""
        start = self.mark()
        verb = command.split()[0]
        self._control.command(command)
        found: list[int] = []

        def seen() -> bool:
            with self._lock:
                for i in range(start, len(self._events)):
                    ev = self._events[i]
                    if "event" in ev and str(ev.get("command", "")).startswith(verb):
                        found.append(i)
                        return True
            return False

        if not wait_for(seen, timeout, 0.01):
            raise PeerError(f"tap {self.name}: no event for {command!r} on its stream")
        return found[0]

    def status(self) -> TapStatus:
        return self._control.status()

    # -- what the stream shows -------------------------------------------------------------------
    def events(self, since: int = 0, kind: str | None = None) -> list[TapEvent]:
        """The tap's own events (not records) from position `since`, optionally of one kind."""
        with self._lock:
            tail = self._events[since:]
        return [e for e in tail if "event" in e and (kind is None or e["event"] == kind)]

    def frames(self, since: int, direction: str) -> list[Frame]:
        """Frames recorded in `direction` ("a>b") from stream position `since`."""
        with self._lock:
            first = bisect.bisect_left(self._frames, since, key=lambda e: e[0])
            return [f for _, d, f in self._frames[first:] if d == direction]

    def op_name(self, frame: Frame) -> str:
        op = self.profile.opcodes.get(frame.op) if frame.op is not None else None
        return op.name if op else "?"

    def wait_frame(
        self, since: int, direction: str, pred: Callable[[Frame], bool], timeout: float
    ) -> bool:
        return wait_for(lambda: any(pred(f) for f in self.frames(since, direction)), timeout)

    def next_frames(self, since: int, direction: str, n: int, timeout: float) -> list[Frame]:
        """The first `n` frames in `direction` from `since`, waiting up to `timeout` (fewer if
        they did not come)."""
        wait_for(lambda: len(self.frames(since, direction)) >= n, timeout)
        return self.frames(since, direction)[:n]
