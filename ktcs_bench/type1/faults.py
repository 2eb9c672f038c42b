"""A byte-level line-fault function for tests and benchmarks of Type I links (SPEC §9).

Owns: `LineFaults`, a seeded callable `bytes -> bytes` that flips bits at a bit-error rate, drops
bytes, and inserts garbage (random bytes, sometimes with a false STX). It plugs into
`VirtualWire(fault=...)`. It is deliberately simple; the tap's fault injection (`ktcs_bench.tap`)
is the lab's tool, this is the link's test bench.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field


@dataclass
class LineFaults:
    """ber: probability a bit is flipped; drop_rate: probability a byte is lost;
    garbage_rate: probability, per chunk, that 1..garbage_max random bytes are inserted."""

    ber: float = 0.0
    drop_rate: float = 0.0
    garbage_rate: float = 0.0
    garbage_max: int = 12
    seed: int = 0
    stx: int = 0x02
    flipped_bits: int = 0
    dropped_bytes: int = 0
    garbage_bytes: int = 0
    rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)

    def __call__(self, data: bytes) -> bytes:
        rng = self.rng
        out = bytearray(data)
        if self.ber:
            nbits = len(out) * 8
            # geometric skips between flipped bits: O(errors), not O(bits)
            pos = self._skip()
            while pos < nbits:
                out[pos >> 3] ^= 1 << (pos & 7)
                self.flipped_bits += 1
                pos += 1 + self._skip()
        if self.drop_rate:
            kept = bytearray(b for b in out if rng.random() >= self.drop_rate)
            self.dropped_bytes += len(out) - len(kept)
            out = kept
        if self.garbage_rate and rng.random() < self.garbage_rate:
            junk = bytearray(rng.randbytes(rng.randint(1, self.garbage_max)))
            if rng.random() < 0.5:
                junk[0] = self.stx  # a false frame start
            at = rng.randint(0, len(out))
            out[at:at] = junk
            self.garbage_bytes += len(junk)
        return bytes(out)

    def _skip(self) -> int:
        u = self.rng.random()
        if u <= 0.0:
            return 0
        return int(math.log(u) / math.log1p(-self.ber))
