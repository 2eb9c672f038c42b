"""Deterministic scenario runs: YAML scenario → endpoints in virtual time → assertions → report.

Must not import the processes or displays (`emulator`, `lab`, `console`, `cli`), sockets, ptys
or the wall clock: a scenario runs the sans-I/O train cores on the virtual clock
(`timed.VirtualClock`) and writes its report files.
"""
