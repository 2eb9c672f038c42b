"""Wire codecs built from the YAML profiles in `protocols/` (SPEC §3, §4).

Owns: CRC functions, frame profiles and opcode tables, the encoder, the streaming decoder and the
hex-text parser. Must not touch: sockets, ptys, clocks -- it is fed bytes and returns records.
"""

from ktcs_bench.codec.frame import Frame, FrameCodec, Garbage, Record
from ktcs_bench.codec.profile import FrameProfile, get_profile, profile_names
from ktcs_bench.codec.stream import StreamDecoder

__all__ = [
    "Frame",
    "FrameCodec",
    "FrameProfile",
    "Garbage",
    "Record",
    "StreamDecoder",
    "get_profile",
    "profile_names",
]
