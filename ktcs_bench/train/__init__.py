"""The train endpoint: dynamics, the ATCS onboard ATP, the kTCS-mode supervision and the ATO.

Everything here is sans-I/O: objects are fed inputs and an explicit time and return outputs and
events. SI units inside (m, s, m/s, m/s²); km/h appears only where data files or reports want it.
Owns the speed–distance data a display draws of a train (`speed_distance`). Must not import the
processes or the displays built on it (`emulator`, `console`, `lab`).
"""
