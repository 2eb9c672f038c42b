"""Taps: record, decode and corrupt the traffic of one link (SPEC §1, §7).

Owns: the sans-I/O tap (`TapCore`, core.py: the fault injectors of both directions, the recorder,
the history and the subscribers' event stream), the runner that binds it to an asyncio loop, the
wall clock and a JSON-lines control port (`Tap`, runner.py), its two adapters (`PtyTap`, pty.py;
`TcpTap`, tcp.py), the command words and their JSON (control.py), the client of a control port
(client.py), the recorder (recorder.py) and the registry of named taps (registry.py). The faults
themselves are `ktcs_bench.faults`; core.py, control.py and recorder.py touch no socket, pty or
clock.
Must not touch: the protocol state machines (type1/, type2/) -- a tap only moves bytes. Must not
import what stands above it: emulator/, lab/, console/, threats/, cli/.
"""

from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.control import Command, parse_command
from ktcs_bench.tap.core import TapCore, TapOutput
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.recorder import Recorder
from ktcs_bench.tap.runner import Tap
from ktcs_bench.tap.tcp import TcpTap

__all__ = [
    "Command",
    "PtyTap",
    "Recorder",
    "Tap",
    "TapClient",
    "TapCore",
    "TapOutput",
    "TcpTap",
    "parse_command",
]
