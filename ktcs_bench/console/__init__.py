"""The CTC operator console (seed 004 Fig. 8) as a web page served from the CTC process.

Owns: the track diagram laid out from station data (`diagram`), the speed–distance provider
interface (`trains`), the aiohttp server with its websocket (`server`), in-process demo
interlockings (`demo`) and the static page (`static/`). What the stations' indications mean and
how a click becomes a control is the CTC's model (`ktcs_bench.ctc`), not the console's.
Must not import `emulator` (the CTC device hosts the console, not the other way round) nor touch
the protocol sessions: it draws `CtcModel.picture`, operates through `Desk.operate` and listens to
the CTC server's `on_event`.
"""

from ktcs_bench.console.server import ConsoleServer
from ktcs_bench.console.trains import EndpointTrains, TrainSource

__all__ = ["ConsoleServer", "EndpointTrains", "TrainSource"]
