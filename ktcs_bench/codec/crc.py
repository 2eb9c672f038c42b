"""CRC functions from their YAML description, computed by crcmod's C extension.

crcmod silently falls back to pure Python when its extension did not build, which is ~50x slower;
`crc_extension_in_use()` says which one runs so the benchmark and `--version`-style checks can tell.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import crcmod

CrcFunction = Callable[[bytes | bytearray | memoryview], int]

CHECK_INPUT = b"123456789"


@dataclass(frozen=True, slots=True)
class CrcSpec:
    """A CRC in the Rocksoft model: polynomial with its top bit, reflection, init, final xor."""

    name: str
    poly: int
    reflect: bool
    init: int
    xor_out: int
    check: int | None = None

    @property
    def width_bits(self) -> int:
        return self.poly.bit_length() - 1

    def function(self) -> CrcFunction:
        fn: CrcFunction = crcmod.mkCrcFun(
            self.poly, initCrc=self.init, rev=self.reflect, xorOut=self.xor_out
        )
        return fn

    def kernel(self) -> tuple[Callable[[object, int, bytes], int], int, bytes, int]:
        """(C function, register init, table, xor_out) for hot loops: crc = xor_out ^ fn(data,
        xor_out ^ init, table). crcmod wraps that C call in a Python closure; calling it directly
        saves a Python frame per frame decoded. Falls back to the closure if crcmod changes.
        Made once per spec: crcmod builds its table in Python (every decoder a lab makes, a
        recorder's after each idle flush included, asks for one)."""
        return _kernel(self)

    def _kernel(self) -> tuple[Callable[[object, int, bytes], int], int, bytes, int]:
        fn = self.function()
        defaults = getattr(fn, "__defaults__", None)
        if defaults and len(defaults) == 3 and callable(defaults[2]):
            crc, table, raw = defaults
            return raw, crc ^ self.xor_out, table, self.xor_out
        return (lambda data, _crc, _table: fn(data)), 0, b"", 0  # noqa: E731 -- crcmod changed


@cache
def _kernel(spec: CrcSpec) -> tuple[Callable[[object, int, bytes], int], int, bytes, int]:
    return spec._kernel()


CRC16_ARC = CrcSpec("crc-16/arc", 0x18005, True, 0x0000, 0x0000, 0xBB3D)
crc16_arc: CrcFunction = CRC16_ARC.function()


def crc_extension_in_use() -> bool:
    """True when crcmod computes in C (its `_crcfunext` extension imported)."""
    module = sys.modules.get("crcmod.crcmod")
    return bool(getattr(module, "_usingExtension", False))
