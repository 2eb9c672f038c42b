"""Type II link (SPEC §4): CTC <-> IXL over TCP.

Owns: the sans-I/O sessions of both ends (`session`, `ixl_side`, `ctc_side`), their events and
settings, the CTC's admission policy, and the asyncio adapters in `net`. Must not touch: the
interlocking or CTC application logic (plugged in through callbacks) or `ktcs_bench/transport/`.
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
