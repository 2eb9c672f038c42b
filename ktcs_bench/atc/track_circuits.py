"""The track-circuit emulator: owns the line, turns train positions into occupancy, and hands each
train the code of the track circuit under its antenna (SPEC §6.4).

A train is given as head and tail chainage (the antenna is at the head; the direction of travel is
tail -> head) and the station track it uses where tracks run side by side. Faults per track
circuit: "failed_occupied", "failed_clear" (wrong side: a train is not seen) and "no_code" (the
code does not reach the antenna). Sans-I/O: `update` is called with positions, no clock.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ktcs_bench.atc.track_codes import AtcCode, most_restrictive
from ktcs_bench.station.model import Line, TrackCircuit

FAULTS = ("failed_occupied", "failed_clear", "no_code")


@dataclass(frozen=True, slots=True)
class TrainPosition:
    train: str
    head_m: float
    tail_m: float
    track: str = "1"  # station track in use (plain-line track circuits carry every track)


class TrackCircuitModel:
    def __init__(self, line: Line) -> None:
        self.line = line
        self.tcs: tuple[TrackCircuit, ...] = line.all_track_circuits()
        self._by_name = {t.name: t for t in self.tcs}
        self.trains: dict[str, TrainPosition] = {}
        self.faults: dict[str, str] = {}
        self.codes: dict[str, AtcCode] = {}
        self._last = self.occupancy()

    def update(self, trains: Iterable[TrainPosition]) -> dict[str, bool]:
        """New train positions (all trains); returns the occupancy changes."""
        self.trains = {t.train: t for t in trains}
        return self._changes()

    def fail(self, tc: str, kind: str) -> dict[str, bool]:
        if kind not in FAULTS:
            raise ValueError(f"unknown track-circuit fault {kind!r} {FAULTS}")
        self._by_name[tc]  # KeyError on an unknown name
        self.faults[tc] = kind
        return self._changes()

    def clear_fault(self, tc: str | None = None) -> dict[str, bool]:
        if tc is None:
            self.faults.clear()
        else:
            self.faults.pop(tc, None)
        return self._changes()

    def shunted(self, tc: TrackCircuit) -> bool:
        """A train's axles are in the track circuit (before any fault)."""
        return self._shunted(tc, self._spans())

    def _spans(self) -> list[tuple[float, float, str]]:
        """Each train's axles: (lowest, highest chainage, track)."""
        return [(min(t.head_m, t.tail_m), max(t.head_m, t.tail_m), t.track)
                for t in self.trains.values()]  # fmt: skip

    @staticmethod
    def _shunted(tc: TrackCircuit, spans: list[tuple[float, float, str]]) -> bool:
        for lo, hi, track in spans:
            if lo < tc.to_m and hi > tc.from_m and tc.on_track(track):
                return True
        return False

    def occupancy(self) -> dict[str, bool]:
        """Every track circuit of the line: occupied as its receiver reports it."""
        out: dict[str, bool] = {}
        spans = self._spans()  # once for all the track circuits (every train move asks)
        for tc in self.tcs:
            fault = self.faults.get(tc.name)
            if fault == "failed_occupied":
                out[tc.name] = True
            elif fault == "failed_clear":
                out[tc.name] = False
            else:
                out[tc.name] = self._shunted(tc, spans) if spans else False
        return out

    def set_codes(self, codes: Mapping[str, AtcCode]) -> None:
        """Codes from the wayside ATCs, per track circuit."""
        self.codes.update(codes)

    def under_antenna(self, train: str) -> str | None:
        t = self.trains[train]
        up = t.head_m >= t.tail_m
        for tc in self.tcs:
            if not tc.on_track(t.track):
                continue
            inside = tc.from_m <= t.head_m < tc.to_m if up else tc.from_m < t.head_m <= tc.to_m
            if inside:
                return tc.name
        return None

    def code_for(self, train: str) -> AtcCode | None:
        """The code the train's antenna picks up; None when no code reaches it. A code given for
        the other direction of travel (tail -> head) is no proceed for this train: it reads the
        most restrictive code."""
        tc = self.under_antenna(train)
        if tc is None or self.faults.get(tc) == "no_code":
            return None
        code = self.codes.get(tc)
        t = self.trains[train]
        running = "up" if t.head_m >= t.tail_m else "down"
        if code is not None and code.direction is not None and code.direction != running:
            return most_restrictive(self.line, -code.gradient_permille)
        return code

    def _changes(self) -> dict[str, bool]:
        now = self.occupancy()
        changed = {k: v for k, v in now.items() if self._last.get(k) != v}
        self._last = now
        return changed
