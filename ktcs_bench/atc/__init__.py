"""Wayside ATC and the track-circuit emulator (SPEC §6.4), sans-I/O.

`TrackCircuitModel(line)`: train positions and point blades -> each train's path over the points
(trailed points, derailments, misrouted trains), occupancy (with injectable faults) and the code
under each train's antenna (SPEC §6.7). `WaysideAtc(line, station)`: occupancy + IXL route state -> TC/TTC/IZC codes
for the IXL and an `AtcCode` (speed code, target speed, gradient, target distance) per track
circuit; the most restrictive code everywhere while its IXL link is in communication error.

Must not import the station-code files (`chart_files`), the links (`type1`, `binding`, `transport`),
`emulator`, `ctc` or `console`; no socket, pty or clock: the ATC device binds it to its links.
"""

from ktcs_bench.atc.track_circuits import TrackCircuitModel, TrainPosition
from ktcs_bench.atc.track_codes import AtcCode, most_restrictive
from ktcs_bench.atc.wayside import AtcEvent, AtcOutput, WaysideAtc

__all__ = [
    "AtcCode",
    "AtcEvent",
    "AtcOutput",
    "TrackCircuitModel",
    "TrainPosition",
    "WaysideAtc",
    "most_restrictive",
]
