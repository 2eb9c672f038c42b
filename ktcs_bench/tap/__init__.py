"""Taps: record, decode and corrupt the traffic of one link (SPEC §1, §7).

Owns: the sans-I/O tap (`TapCore`, core.py: the fault injectors of both directions, the recorder,
the history and the subscribers' event stream), the command words and their JSON (control.py) and
the recorder (recorder.py) -- what this package's own namespace offers, and all of it free of I/O
and clocks -- and, each in its own module: the runner that binds the core to an asyncio loop, the
wall clock and a JSON-lines control port (`runner.Tap`), its adapters (`pty.PtyTap`,
`tcp.TcpTap`, and `wire.WireTap` for a lab in one process), the client of a control port (`client.TapClient`) and the registry of named taps
(registry.py). The faults themselves are `ktcs_bench.faults`.
Must not touch: the protocol state machines (type1/, type2/) -- a tap only moves bytes. Must not
import what stands above it: emulator/, lab/, console/, threats/, cli/. This file imports no
adapter, so that importing the core loads no socket, pty, loop or clock.
"""

from ktcs_bench.tap.control import Command, parse_command
from ktcs_bench.tap.core import Subscription, TapCore, TapOutput
from ktcs_bench.tap.recorder import Recorder

__all__ = ["Command", "Recorder", "Subscription", "TapCore", "TapOutput", "parse_command"]
