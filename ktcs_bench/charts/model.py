"""The in-memory code chart and its YAML loader.

Chart file (one per link and direction, under `code_charts/`):

    chart: st20-ixl-to-ctc          # unique name
    protocol: type2                 # type1 | type2
    direction: IXL->CTC             # sender->receiver
    station: 20                     # optional
    codes:                          # number = 1-based position in this list
      - {name: LOC20, type: LOC, sequence: 1, status: "1 local mode"}
      - {name: CTC20, type: CTC, sequence: 2, status: "1 center mode"}

`sequence` (Table 2's column) is optional; when present it must equal the code's position.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ktcs_bench.datafiles import load_yaml
from ktcs_bench.errors import ConfigError


@dataclass(frozen=True, slots=True)
class Code:
    number: int
    name: str
    type: str
    status: str = ""


@dataclass(frozen=True)
class CodeChart:
    name: str
    protocol: str
    direction: str
    codes: tuple[Code, ...]
    station: int | None = None
    _by_name: dict[str, Code] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._by_name.update({c.name: c for c in self.codes})

    def __len__(self) -> int:
        return len(self.codes)

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


def load_chart(path: str | Path) -> CodeChart:
    """Load and schema-check one chart file; errors name the file, the key path and the problem."""
    raw = load_yaml(path)
    if not isinstance(raw, dict):
        raise ConfigError(path, "", "a chart must be a mapping with keys chart, protocol, codes")
    for key in ("chart", "protocol", "direction", "codes"):
        if key not in raw:
            raise ConfigError(path, key, "missing key")
    if raw["protocol"] not in ("type1", "type2"):
        raise ConfigError(path, "protocol", f"must be type1 or type2, not {raw['protocol']!r}")
    items = raw["codes"]
    if not isinstance(items, list):
        raise ConfigError(path, "codes", "must be a list of {name, type, status}")
    codes: list[Code] = []
    seen: dict[str, int] = {}
    for i, item in enumerate(items):
        place = f"codes[{i}]"
        if not isinstance(item, dict) or not isinstance(item.get("name"), str):
            raise ConfigError(path, place, "each code needs a string 'name'")
        name = item["name"]
        if name in seen:
            other = f"codes[{seen[name]}]"
            raise ConfigError(path, f"{place}.name", f"duplicate code {name!r} (also {other})")
        seen[name] = i
        seq = item.get("sequence")
        if seq is not None and seq != i + 1:
            raise ConfigError(
                path, f"{place}.sequence", f"is {seq!r}, but the code is number {i + 1}"
            )
        codes.append(Code(i + 1, name, str(item.get("type", "")), str(item.get("status", ""))))
    station = raw.get("station")
    if station is not None and not isinstance(station, int):
        raise ConfigError(path, "station", "must be an integer station number")
    return CodeChart(
        str(raw["chart"]), raw["protocol"], str(raw["direction"]), tuple(codes), station
    )
