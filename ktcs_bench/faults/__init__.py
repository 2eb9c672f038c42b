"""Faults of a line: what can happen to the bytes between two ends of a link (SPEC §9).

Owns: the one fault injector of the bench (`injector.py`): the faults (`BitErrors`, `ByteLoss`,
`Noise`, `DropBytes`, `DropFrame`, `DuplicateFrame`, `ReorderFrames`, `CorruptFrame`,
`TruncateFrame`, `InsertGarbage`, `Delay`, `Cut`), their words (`ber 1e-3 a>b`) and JSON forms, and
`FaultInjector`, which applies them to one direction's byte stream. It is sans-I/O and
deterministic: bytes and `now` in, bytes and the next deadline out, randomness from a seeded
`random.Random`. The taps (`ktcs_bench.tap`) put it between real ends, the virtual wire
(`ktcs_bench.transport.virtual`) between two links on a virtual clock, and the tests use it.

Not here: faults of a device (point machines, lamps, relays: `field/`; faulty protocol behaviour:
`emulator/variants.py`). Must not import: sockets, ptys, asyncio, threads, clocks (`time`), nor
`tap`, `transport`, `type1`, `type2` -- only the codec (to find frames) and the error types.
"""

from ktcs_bench.faults.injector import (
    FAULTS,
    BitErrors,
    ByteLoss,
    CorruptFrame,
    Cut,
    Delay,
    DropBytes,
    DropFrame,
    DuplicateFrame,
    Fault,
    FaultInjector,
    FaultStats,
    InsertGarbage,
    Noise,
    ReorderFrames,
    TruncateFrame,
    fault_from_json,
)

__all__ = [
    "FAULTS",
    "BitErrors",
    "ByteLoss",
    "CorruptFrame",
    "Cut",
    "Delay",
    "DropBytes",
    "DropFrame",
    "DuplicateFrame",
    "Fault",
    "FaultInjector",
    "FaultStats",
    "InsertGarbage",
    "Noise",
    "ReorderFrames",
    "TruncateFrame",
    "fault_from_json",
]
