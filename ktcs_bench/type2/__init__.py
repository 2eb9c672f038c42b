"""Type II link (SPEC §4): CTC <-> IXL over TCP.

Owns: the sans-I/O sessions of both ends (`session`, `ixl_side`, `ctc_side`), their events and
settings, and the CTC's admission policy -- no I/O and no clock anywhere in it. Its asyncio adapters
(the session pump, the CTC's server, the IXL's client) are `ktcs_bench.transport`'s, beside Type I's.
Must not import: the interlocking or the CTC's application (`ixl`, `ctc`: they plug in through the
`IxlApplication` / `CtcApplication` protocols), `emulator`, `console` or `ktcs_bench/transport/`.
"""

from ktcs_bench.type2.admission import AdmissionPolicy, BadFrameMeter, Decision
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.ctc_side import CtcConnection
from ktcs_bench.type2.ixl_side import IxlSession
from ktcs_bench.type2.session import SessionState, Type2Session

__all__ = [
    "AdmissionPolicy",
    "BadFrameMeter",
    "CtcConnection",
    "Decision",
    "IxlSession",
    "SessionState",
    "Type2Config",
    "Type2Session",
]
