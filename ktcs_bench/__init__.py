"""ktcs-bench: an emulated kTCS signalling lab (CTC, IXL, ATC, trackside, trains) on one machine.

The package is sans-I/O at its core (codecs, link state machines, interlocking, ATP) with thin
adapters at the edge (ptys, TCP, clocks) and one CLI on top (`ktcs-bench`).
"""

__version__ = "0.1.0"
