"""Emulator processes: the sans-I/O objects (IXL, trackside, ATC, track circuits, CTC, train) bound
to real ptys, serial ports and TCP sockets on an asyncio loop with the wall clock.

Owns: the Type I code port (`code_link`: chart <-> frames), the field bus between the
track-circuit emulator and its clients, each device's process main, and the JSON-lines control port
every device offers (its framing, shared with the taps: `ktcs_bench.transport.jsonlines`). Must not
hold protocol or signalling logic -- that lives in type1/, type2/, ixl/, field/, atc/, train/ and
ctc/. It may import the console (the CTC device hosts it); nothing below it (console, ctc, tap,
transport, the cores) may import it.
"""
