"""Exhaustive verification of the interlocking (SPEC §13).

`table`: each station's control table, derived from its data. `data`: the routes checked against
the point geometry (paths, positions, track circuits, overlap, flank protection, conflicts).
`explore`: every reachable state of the real `Interlocking` core within a stated bound, checked
against SPEC §6.2 invariants 1-6 after every transition.
"""
