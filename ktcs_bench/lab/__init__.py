"""The lab: a topology file (devices, links, taps) and the orchestrator that starts every device as
its own OS process, linked over real ptys (Type I, through taps) and TCP (Type II, through taps).

Owns: `emulators/labs/*.yaml` loading and checking, process launch and supervision, the link map,
the live status view and the lab's control port (`lab down`, `lab restart`). The devices' logic is
elsewhere (emulator/ binds it to I/O; ixl/, atc/, field/, type1/, type2/ hold it). Must not
import `cli` (the command is built on the lab, not the other way round).
"""
