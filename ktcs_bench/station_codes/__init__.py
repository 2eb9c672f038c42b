"""The station-code layer (SPEC §3.5, §5), under the IXL, the trackside, the ATC and the CTC.

Owns: the code names (`names`: the one place a name is spelled, `CodeName` a name taken apart),
the code chart (`chart`: numbered codes of one link and direction), and what station data gives
(`stations`: each station link's chart, `StationCodes.parse_code` for what a name means, the TTC
totalisers). Pure: no files, no links, no clock.
Imports only station data (`ktcs_bench.station.model`). Must not import the cores (`ixl`,
`field`, `atc`), `chart_files` (the YAML files and `chart check`, built on this), the links
(`type1`, `type2`, `binding`, `transport`), `emulator`, `ctc` or `console`.
"""

from ktcs_bench.station_codes.chart import Code, CodeChart
from ktcs_bench.station_codes.names import CodeName, Function
from ktcs_bench.station_codes.stations import (
    LINKS,
    NEIGHBOUR_LINKS,
    ChartSpec,
    StationCodes,
    Totaliser,
    build_specs,
    chart_spec,
    link_charts,
    neighbour_intervals,
    reverse,
    station_chart,
    station_links,
    totalisers,
)

__all__ = [
    "LINKS",
    "NEIGHBOUR_LINKS",
    "ChartSpec",
    "Code",
    "CodeChart",
    "CodeName",
    "Function",
    "StationCodes",
    "Totaliser",
    "build_specs",
    "chart_spec",
    "link_charts",
    "neighbour_intervals",
    "reverse",
    "station_chart",
    "station_links",
    "totalisers",
]
