"""Integration test procedures: a YAML file of setup, actions, faults, waits and expectations
with time limits, run against a lab through `LabAccess` -- live (`lab up`, the wall clock, the
real wires) or in one process (the virtual clock) -- with a verdict per step, the timeline of
the run, and reports an engineer can hand over (JUnit XML, JSON, self-contained HTML).

Owns: the file format and its checks (`model`, `steps`, `expect`, `names`), the run (`runner`)
and its reports (`report`). Reaches a lab only through `lab.access.LabAccess`; must not import
`cli`, `emulator` or `console` (they sit above it or beside it).
"""
