"""Taps: record, decode and corrupt the traffic of one link (SPEC §1, §7).

Owns: the proxies between a link's two ends (`PtyTap`, `TcpTap`), the sans-I/O recorder they are
built on, the control language and its port, and the registry of named taps. The faults they
inject are `ktcs_bench.faults`.
Must not touch: the protocol state machines (type1/, type2/) -- a tap only moves bytes. Must not
import what stands above it: emulator/, lab/, console/, cli/.
"""

from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.control import Command, parse_command
from ktcs_bench.tap.link import PtyTap, Tap, TcpTap
from ktcs_bench.tap.recorder import Recorder

__all__ = [
    "Command",
    "PtyTap",
    "Recorder",
    "Tap",
    "TapClient",
    "TcpTap",
    "parse_command",
]
