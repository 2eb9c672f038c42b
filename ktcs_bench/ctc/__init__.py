"""The CTC's application, under its devices and its console.

Owns: what the CTC knows of each station (`tables`: indication tables and link standing, fed by
the Type II server) and what it means to the operator (`model`). Pure: no sockets, no clock, no
asyncio. Must not import `emulator`, `console` or `type2`'s asyncio adapters (the server reaches the
tables through the `CtcApplication` protocol it declares).
"""

from ktcs_bench.ctc.tables import IndicationTable, IndicationTables

__all__ = ["IndicationTable", "IndicationTables"]
