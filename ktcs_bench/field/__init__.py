"""Trackside I/O emulation (SPEC §6.3), sans-I/O: point machines, signal lamps, track relays.

`Trackside(view)` reads the IXL->IO chart codes (point demands, lamp commands), follows train
occupancy from the track-circuit model, runs point throws against `now`, takes injected faults,
and reports the IO->IXL chart codes (SNI/SRN/SRI/SNR, LPS/LFI, TC relays) as changes.

Must not import the station-code files (`chart_files`), the links (`type1`, `binding`, `transport`),
`emulator` or the IXL; no socket, pty or clock: the trackside device binds it to its links.
"""

from ktcs_bench.field.points import PointMachine
from ktcs_bench.field.relays import TrackRelay
from ktcs_bench.field.signals import SignalHead
from ktcs_bench.field.trackside import FieldEvent, FieldOutput, Trackside

__all__ = ["FieldEvent", "FieldOutput", "PointMachine", "SignalHead", "TrackRelay", "Trackside"]
