"""Station and line data (SPEC §2, §6.2): the model every emulator runs on, and its checked loader.

`load_line()` reads `emulators/lines/reference.yaml` and the station files it names; every error
is a `ConfigError` naming the file, the key path and the problem.

Must not import anything built on station data (`station_codes`, `chart_files`, the cores,
`lab`): it is the bottom of the signalling layers.
"""

from ktcs_bench.station.loader import default_line_path, load_line, load_station
from ktcs_bench.station.model import (
    Interval,
    Line,
    Point,
    PointSetting,
    Route,
    Signal,
    Station,
    StationView,
    TrackCircuit,
)

__all__ = [
    "Interval",
    "Line",
    "Point",
    "PointSetting",
    "Route",
    "Signal",
    "Station",
    "StationView",
    "TrackCircuit",
    "default_line_path",
    "load_line",
    "load_station",
]
