"""TCP connections that never meet themselves.

A connection to a local port nobody listens on can, once in a few tens of thousands of tries, be
given that same port as its own source port and "connect" to itself (TCP simultaneous open). A
client that retries against a device being restarted would then hold the very port the device
comes back on. `open_tcp` refuses such a connection as the refusal it really is.
"""

from __future__ import annotations

import asyncio

from ktcs_bench.transport import net

LIMIT = net.LIMIT


async def open_tcp(
    host: str, port: int, limit: int = LIMIT
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await net.open_connection(host, port, limit=limit)
    if writer.get_extra_info("sockname") == writer.get_extra_info("peername"):
        writer.close()
        raise ConnectionRefusedError(f"nothing listens on {host}:{port}")
    return reader, writer
