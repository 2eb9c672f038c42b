"""Adapters that bind sans-I/O links to wires and clocks (SPEC §2, §3).

Owns: the `Transport` shape (base.py), pty pairs and pyserial URLs with line-rate pacing
(serial.py), the asyncio wall-clock driver (aio.py) and the virtual-clock driver (virtual.py).
Must not contain protocol rules: those live in `ktcs_bench.type1`.
"""
