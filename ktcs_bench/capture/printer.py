"""Decoded capture records printed as they come (`monitor`, `replay`): each frame in the console's
words or as a JSON line (SPEC §7 keys, with time and direction), and the ARQ events it makes.
Formats the times its records carry; reads no clock."""

from __future__ import annotations

import json
import sys
import time
from collections import defaultdict
from collections.abc import Mapping
from typing import TextIO

from ktcs_bench.capture.arq import ArqTracker
from ktcs_bench.capture.records import CaptureRecord
from ktcs_bench.codec.frame import Frame, Record
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.codec.render import DIM, RESET, YELLOW, to_json, to_text
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.station_codes.chart import CodeChart


def print_json_line(obj: Mapping[str, object], stream: TextIO = sys.stdout) -> None:
    stream.write(json.dumps(obj, ensure_ascii=False, separators=(", ", ": ")) + "\n")


def format_time(t: float | None) -> str:
    if t is None:
        return "-"
    if t < 1e9:  # relative (a capture without a start time)
        return f"{t:.6f}"
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t * 1e6) % 1_000_000:06d}"


class FramePrinter:
    """Decodes capture records frame by frame and prints them (text or JSON), with ARQ events."""

    def __init__(
        self,
        profile: FrameProfile,
        *,
        chart: CodeChart | None = None,
        colour: bool = False,
        as_json: bool = False,
        stream: TextIO = sys.stdout,
        charts: Mapping[str, CodeChart] | None = None,
    ) -> None:
        self.profile = profile
        self.chart = chart
        self.charts = dict(charts or {})
        """The chart of the frames each end sends, by its name (a tap's `ixl18` of
        `ixl18>ixl20`): a link carries a chart each way; `chart` names the others."""
        self.colour = colour
        self.as_json = as_json
        self.stream = stream
        self.arq = ArqTracker(profile)
        self._offsets: dict[str, int] = defaultdict(int)
        self.frames = 0
        self.bad = 0

    def decode(self, record: CaptureRecord) -> list[Record]:
        dec = StreamDecoder(self.profile, offset=self._offsets[record.direction])
        self._offsets[record.direction] += len(record.data)
        return dec.feed(record.data) + dec.close()

    def show(self, record: CaptureRecord, note: str = "") -> list[Record]:
        decoded = self.decode(record)
        for rec in decoded:
            events: list[str] = []
            if isinstance(rec, Frame):
                self.frames += 1
                self.bad += rec.error is not None
                events = self.arq.observe(record.direction, rec, record.time)
            if self.as_json:
                line = {"time": record.time, "direction": record.direction,
                        **to_json(rec, self.profile), "arq": events}  # fmt: skip
                print_json_line(line, self.stream)
                continue
            label = f"{format_time(record.time)} {record.direction}{note}  "
            chart = self.charts.get(record.direction.split(">")[0], self.chart)
            lines = [to_text(rec, self.profile, chart, self.colour, label)]
            for ev in events:
                text = f"  ARQ: {ev}"
                lines.append(f"{YELLOW}{text}{RESET}" if self.colour else text)
            self.stream.write("\n".join(lines) + "\n\n")
        self.stream.flush()
        return decoded

    def event(self, event: Mapping[str, object]) -> None:
        """A tap event (fault command, connection) -- shown in text mode only."""
        if self.as_json:
            return
        detail = " ".join(f"{k}={v}" for k, v in event.items() if k not in ("time", "event"))
        t = event.get("time")
        when = format_time(t if isinstance(t, int | float) else None)
        text = f"-- {when} {event.get('event')}: {detail}"
        self.stream.write((f"{DIM}{text}{RESET}" if self.colour else text) + "\n")
        self.stream.flush()
