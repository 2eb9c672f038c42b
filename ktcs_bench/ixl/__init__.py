"""The electronic interlocking (SPEC §6.2) as a sans-I/O object: no sockets, no clock, no sleep.

`Interlocking(view)` takes controls, Type I code changes, link states and `now`, and returns the
indication, ATC and trackside code changes, control results, events and its next deadline.
Modules: `modes` (center/local, CMR), `routes` (locking and release), `points`, `signals`,
`reasons` (CONTROL_RESULT reason numbers), `interlocking` (the station as a whole).

Must not import the station-code files (`chart_files`), the links (`type1`, `type2`, `binding`,
`transport`), `emulator`, `ctc` or `console`; no socket, pty or clock (`timed` drives it).
"""

from ktcs_bench.ixl.interlocking import ControlResult, Interlocking, IxlEvent, IxlOutput
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.ixl.routes import RouteStatus

__all__ = [
    "ControlResult",
    "IxlEvent",
    "Interlocking",
    "IxlOutput",
    "Mode",
    "Reason",
    "RouteStatus",
]
