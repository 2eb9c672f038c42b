"""Adapters that bind sans-I/O links to wires and clocks (SPEC §2, §3).

Owns: the `Transport` shape (base.py), pty pairs and pyserial URLs with line-rate pacing
(serialport.py), TCP connections (tcp.py), JSON lines over asyncio streams -- the bench's own
control ports and field bus, devices' and taps' alike (jsonlines.py) --, a Type I link run over a
transport on the asyncio loop (aio.py), the Type II adapters (type2_pump.py: one session on one
stream; ctc_server.py: accept, TLS, admission, one link per station; ixl_client.py: connect,
back-off), two links joined by an in-memory wire on the virtual clock
(virtual.py), endpoints and ports as a user writes them (endpoints.py), and the memory network of a
lab run in one process (memory.py: streams and paced serial wires) behind the one seam every
device's TCP goes through (net.py). The clocks' drivers
themselves are `ktcs_bench.timed`.
Must not contain protocol rules (they live in `ktcs_bench.type1` and `ktcs_bench.type2`) nor fault logic (the wire's
faults are `ktcs_bench.faults`' injector). Must not import what stands above it: tap/, emulator/,
lab/, console/, cli/.
"""

from ktcs_bench.transport.aio import LinkRunner
from ktcs_bench.transport.base import Transport, TransportBase, TransportClosed
from ktcs_bench.transport.serialport import (
    PacedWriter,
    PtyTransport,
    SerialTransport,
    open_transport,
)
from ktcs_bench.transport.virtual import VirtualBench, VirtualWire

__all__ = [
    "LinkRunner",
    "PacedWriter",
    "PtyTransport",
    "SerialTransport",
    "Transport",
    "TransportBase",
    "TransportClosed",
    "VirtualBench",
    "VirtualWire",
    "open_transport",
]
