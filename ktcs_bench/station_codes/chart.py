"""The code chart (SPEC §3.5, §5): one link's codes in one direction, numbered.

A code's number is its 1-based position in the chart (Table 2 "Sequence"); Type I ALL_INFO byte
k-1 carries code k, a Type II item names code k by k. The charts a station's links carry are
derived from its data (`station_codes.stations`); `chart_files.files` reads and writes them as YAML.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Code:
    number: int
    name: str
    type: str
    status: str = ""


@dataclass(frozen=True)
class CodeChart:
    name: str
    protocol: str  # type1 | type2
    direction: str  # sender->receiver, e.g. IXL->CTC
    codes: tuple[Code, ...]
    station: int | None = None
    _by_name: dict[str, Code] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._by_name.update({c.name: c for c in self.codes})

    def __len__(self) -> int:
        return len(self.codes)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def name_of(self, number: int) -> str | None:
        """The mnemonic of code `number` (1-based), or None when the chart has no such code."""
        if 1 <= number <= len(self.codes):
            return self.codes[number - 1].name
        return None

    def number_of(self, name: str) -> int:
        try:
            return self._by_name[name].number
        except KeyError:
            raise KeyError(f"code {name!r} is not in chart {self.name}") from None

    @property
    def names(self) -> tuple[str, ...]:
        """Every code's name, in number order."""
        return tuple(c.name for c in self.codes)
