"""The CTC's application, under its device process and its web console.

Owns: what the CTC knows of each station (`tables`: indication tables and link standing, fed by
the Type II server through its `CtcApplication` protocol), what that means to the operator and
which control each operator command is (`model`: one reading of a station's indications, code
charts derived from station data), the command log (`log`), and the desk (`desk`) that sends a
command through the CTC server and logs what came of it; and automatic route setting: the train
describer (`describer`: train numbers stepped from berth to berth as track circuits occupy and
clear) and ARS (`ars`: each train's routes asked for from its timetable, and why it waits).
`tables`, `model`, `log`, `describer` and `ars` are pure (no sockets, no clock); `desk` is the one
part that awaits the server, imported from `ktcs_bench.ctc.desk` (not here: importing the package
brings in no I/O).
Must not import `emulator` or `console` (they are built on this package), nor the interlocking.
"""

from ktcs_bench.ctc.log import CommandLog, command_words
from ktcs_bench.ctc.model import Action, CtcModel, StationModel, signal_name
from ktcs_bench.ctc.tables import IndicationTable, IndicationTables

__all__ = [
    "Action",
    "CommandLog",
    "CtcModel",
    "IndicationTable",
    "IndicationTables",
    "StationModel",
    "command_words",
    "signal_name",
]
