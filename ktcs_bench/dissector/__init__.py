"""A Wireshark dissector (Lua) generated from the wire profiles (SPEC §11, issue 17).

Owns: turning `FrameProfile`s (and a code chart) into one self-contained Lua file -- protocols
`ktcs1` (Type I, LINKTYPE_USER0) and `ktcs2` (Type II, TCP) -- and finding Wireshark's personal
plugin folder. Must not touch: the codecs' behaviour; it reads profiles, it never builds them.
"""

from ktcs_bench.dissector.generate import (
    PLUGIN_NAME,
    crc_table,
    generate,
    lua_literal,
    personal_lua_plugins,
    profile_data,
)

__all__ = [
    "PLUGIN_NAME",
    "crc_table",
    "generate",
    "lua_literal",
    "personal_lua_plugins",
    "profile_data",
]
