"""Code chart files (SPEC §3.5, §5): the YAML files under `code_charts/`, and their check.

A code's number is its 1-based position in the chart (Table 2 "Sequence"); Type I ALL_INFO byte k-1
carries code k. Owns: reading and writing chart files (`files`: `load_chart`, `generate`) and
`chart check` (`check`: the files against the station data and against what the emulators send).
The charts themselves, and what each name means, are the station-code layer's (`station_codes`),
which the emulators use directly: nothing below reads these files.
Sits above the cores: `check` builds the interlocking, trackside, ATC and the CTC's model and binds
them as the emulators do. Must not be imported by `station_codes`, `binding`, the cores,
`type1`/`type2` or `emulator`; must not import `emulator`, `lab` or `cli`.
"""
