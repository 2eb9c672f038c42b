"""Taps: record, decode and corrupt the traffic of one link (SPEC §1, §7).

Owns: the proxies between a link's two ends (`PtyTap`, `TcpTap`), the sans-I/O fault injector and
recorder they are built on, the control language and its port, and the registry of named taps.
Must not touch: the protocol state machines (type1/, type2/) -- a tap only moves bytes.
"""

from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.control import Command, parse_command
from ktcs_bench.tap.faults import (
    BitErrors,
    Cut,
    Delay,
    DropBytes,
    DropFrame,
    DuplicateFrame,
    Fault,
    FaultInjector,
    InsertGarbage,
    ReorderFrames,
)
from ktcs_bench.tap.link import PtyTap, Tap, TcpTap
from ktcs_bench.tap.recorder import Recorder

__all__ = [
    "BitErrors",
    "Command",
    "Cut",
    "Delay",
    "DropBytes",
    "DropFrame",
    "DuplicateFrame",
    "Fault",
    "FaultInjector",
    "InsertGarbage",
    "PtyTap",
    "Recorder",
    "ReorderFrames",
    "Tap",
    "TapClient",
    "TcpTap",
    "parse_command",
]
