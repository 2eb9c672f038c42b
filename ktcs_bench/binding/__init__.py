"""One binding between a core and its links (SPEC §3.5, §4): code names on the core's side, code
numbers on the link's.

Owns: the number <-> name mapping of a link's two charts, the changes owed to a link that was
down, and a control's number -> name on its way to the core (`ControlLink`, the IXL's Type II
application). The core's changes arrive already differenced (the core's one diff against what it
sent) and a full state is read from the core's own table: the binding neither compares again nor
keeps a second copy.
Sans-I/O: fed names and numbers, returns items to send; used by the Type I code port
(`emulator.code_link`), the IXL's Type II side (`emulator.ixl`, `console.demo`), and by virtual
links alike.
Imports only `station_codes`. Must not import asyncio, the cores (`ixl`, `field`,
`atc`: they plug in by the names they give and take), the link protocols (`type1`, `type2`),
`transport`, `emulator`, `ctc` or `console`.
"""

from ktcs_bench.binding.link import ControlLink, LinkBinding

__all__ = ["ControlLink", "LinkBinding"]
