"""What a lab and its line call things, for checking a procedure's words before anything runs:
stations and their signals, points and routes, track circuits, devices by kind and station,
links, trains. A name that is not there is a `StepError` saying what there is."""

from __future__ import annotations

from dataclasses import dataclass, field

from ktcs_bench import kinds
from ktcs_bench.ctc.model import signal_name
from ktcs_bench.lab.topology import Lab, LinkSpec
from ktcs_bench.station.model import Line, TrackCircuit


class StepError(ValueError):
    """A step's words are wrong: the loader turns it into one ConfigError (file, step, why)."""


def _choices(names: object) -> str:
    items = sorted(str(n) for n in names)  # type: ignore[attr-defined]
    shown = ", ".join(items[:12])
    return shown + (", ..." if len(items) > 12 else "")


@dataclass
class LabNames:
    lab: Lab
    line: Line
    trains: set[str] = field(default_factory=set)  # placed by the setup, or train devices

    def __post_init__(self) -> None:
        for d in self.lab.of_kind(kinds.TRAIN):
            self.trains.add(str(d.options.get(kinds.TRAIN, d.name)))
        self.tcs: dict[str, TrackCircuit] = {t.name: t for t in self.line.all_track_circuits()}

    # -- stations --------------------------------------------------------------------------------
    def station(self, word: str) -> int:
        try:
            number = int(word)
        except ValueError:
            raise StepError(f"{word!r} is not a station number") from None
        if number not in self.line.stations:
            raise StepError(f"no station {number} (stations: {_choices(self.line.stations)})")
        return number

    def signal(self, station: int, word: str) -> str:
        name = signal_name(word)
        names = [s.name for s in self.line.station(station).signals]
        if name not in names:
            raise StepError(
                f"station {station} has no signal {word!r} (signals: {_choices(names)})"
            )
        return name

    def point(self, station: int, word: str) -> str:
        names = [p.name for p in self.line.station(station).points]
        if word not in names:
            raise StepError(f"station {station} has no point {word!r} (points: {_choices(names)})")
        return word

    def route(self, station: int, word: str) -> str:
        names = [r.name for r in self.line.station(station).routes]
        if word not in names:
            raise StepError(f"station {station} has no route {word!r} (routes: {_choices(names)})")
        return word

    def track_circuit(self, word: str) -> TrackCircuit:
        tc = self.tcs.get(word.upper())
        if tc is None:
            raise StepError(f"no track circuit {word!r} on line {self.line.name}")
        return tc

    # -- devices, links, trains ------------------------------------------------------------------
    def device(self, word: str, kind: str | None = None) -> str:
        d = self.lab.devices.get(word)
        if d is None or (kind is not None and d.kind != kind):
            names = [n for n, x in self.lab.devices.items() if kind is None or x.kind == kind]
            what = f"{kind} " if kind else ""
            raise StepError(f"lab {self.lab.name} has no {what}device {word!r} ({_choices(names)})")
        return word

    def device_of(self, kind: str, station: int | None = None) -> str:
        for d in self.lab.devices.values():
            if d.kind == kind and (station is None or d.station == station):
                return d.name
        at = f" at station {station}" if station is not None else ""
        raise StepError(f"lab {self.lab.name} has no {kind}{at}")

    def link(self, word: str) -> LinkSpec:
        for lk in self.lab.links:
            if lk.name == word:
                return lk
        raise StepError(
            f"lab {self.lab.name} has no link {word!r} ({_choices(lk.name for lk in self.lab.links)})"
        )

    def tapped_link(self, word: str) -> LinkSpec:
        lk = self.link(word)
        if not lk.tap:
            raise StepError(f"link {word} has no tap in lab {self.lab.name}: no fault, no capture")
        return lk

    def train(self, word: str) -> str:
        if word not in self.trains:
            raise StepError(f"no train {word!r} (trains: {_choices(self.trains) or 'none'})")
        return word

    def train_device(self, train: str) -> str | None:
        """The device running train `train`, None for a train the procedure places itself."""
        for d in self.lab.of_kind(kinds.TRAIN):
            if str(d.options.get(kinds.TRAIN, d.name)) == train:
                return d.name
        return None

    def station_of(self, tc: TrackCircuit) -> int:
        return tc.station
