"""The CTC operator console (seed 004 Fig. 8) as a web page served from the CTC process.

Owns: the track diagram laid out from station data (`diagram`), the station picture derived from
the CTC's indication tables and operator actions mapped to control codes (`state`), the
speed–distance provider interface (`trains`), the aiohttp server with its websocket (`server`),
in-process demo interlockings (`demo`) and the static page (`static/`). It must not touch the
protocol sessions: it only reads `CtcServer.stations` and calls `CtcServer.control`.
"""

from ktcs_bench.console.server import ConsoleServer, load_charts
from ktcs_bench.console.trains import EndpointTrains, SpeedDistance, TrainSource

__all__ = ["ConsoleServer", "EndpointTrains", "SpeedDistance", "TrainSource", "load_charts"]
