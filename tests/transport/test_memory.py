"""The in-memory network: streams and serial wires in one process, as TCP and lines behave
(issue 15 part 2)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

import pytest

from ktcs_bench.timed.vloop import VirtualTimeLoop
from ktcs_bench.transport import memory, net
from ktcs_bench.transport.base import TransportClosed
from ktcs_bench.transport.serialport import open_transport


def on_memory(main: Callable[[], Awaitable[Any]]) -> Any:
    loop = VirtualTimeLoop()
    memory.attach(loop)
    try:
        return loop.run_until_complete(main())
    finally:
        memory.detach(loop)
        loop.close()


def test_a_stream_carries_bytes_both_ways_and_close_is_end_of_file() -> None:
    async def main() -> tuple[bytes, bytes, bytes]:
        got: list[bytes] = []

        async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            line = await reader.readline()
            got.append(line)
            writer.write(line.upper())
            writer.write(b"bye\n")
            writer.close()

        server = await net.start_server(echo, "127.0.0.1", 0)
        host, port = net.server_address(server)
        reader, writer = await net.open_connection(host, port)
        writer.write(b"hello\n")
        answer = await reader.readline()
        rest = await reader.read()  # everything written before the close, then end of file
        return got[0], answer, rest

    assert on_memory(main) == (b"hello\n", b"HELLO\n", b"bye\n")


def test_nothing_listening_is_connection_refused_and_a_closed_server_refuses() -> None:
    async def main() -> None:
        with pytest.raises(ConnectionRefusedError):
            await net.open_connection("127.0.0.1", 5000)
        server = await net.start_server(lambda r, w: None, "127.0.0.1", 5000)
        reader, writer = await net.open_connection("127.0.0.1", 5000)
        with pytest.raises(OSError, match="in use"):
            await net.start_server(lambda r, w: None, "127.0.0.1", 5000)
        server.close()
        with pytest.raises(ConnectionRefusedError):
            await net.open_connection("127.0.0.1", 5000)

    on_memory(main)


def test_dropping_an_owner_resets_its_connections_as_a_dead_process_does() -> None:
    async def main() -> None:
        network = memory.network_of(asyncio.get_running_loop())
        assert network is not None
        served = asyncio.Event()

        async def hold(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            served.set()
            await reader.read()

        token = memory.OWNER.set("device")
        await net.start_server(hold, "127.0.0.1", 7000)
        memory.OWNER.reset(token)
        reader, _ = await net.open_connection("127.0.0.1", 7000)
        await served.wait()
        network.drop("device")
        with pytest.raises(ConnectionResetError):
            await reader.read()
        with pytest.raises(ConnectionRefusedError):
            await net.open_connection("127.0.0.1", 7000)

    on_memory(main)


def test_a_reader_that_stops_reading_pauses_delivery_and_loses_nothing() -> None:
    async def main() -> int:
        sent = bytes(range(256)) * 2048  # 512 KiB, far above the reader's limit

        async def pour(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            writer.write(sent)
            writer.close()

        await net.start_server(pour, "127.0.0.1", 7001, limit=1024)
        reader, _ = await net.open_connection("127.0.0.1", 7001, limit=1024)
        await asyncio.sleep(1.0)  # nothing read meanwhile
        got = await reader.read()
        assert got == sent
        return len(got)

    assert on_memory(main) == 512 * 1024


def test_tls_is_refused_in_process_with_a_clear_error() -> None:
    import ssl

    async def main() -> None:
        with pytest.raises(Exception, match="TLS runs in a live lab only"):
            await net.open_connection("127.0.0.1", 1, ssl=ssl.create_default_context())

    on_memory(main)


def test_a_virtual_wire_is_paced_at_the_line_rate() -> None:
    """1000 bytes at 9600 bit/s (10 bits a byte) arrive over 1.0417 s, the last when its last bit
    would have: the same pacing as the virtual wire of the link tests."""

    async def main() -> list[tuple[float, int]]:
        loop = asyncio.get_running_loop()
        network = memory.network_of(loop)
        assert network is not None
        network.join_serial("L/a", "L/b")
        a = open_transport("virtual://L/a", line_rate=9600)
        b = open_transport("virtual://L/b", line_rate=9600)
        arrivals: list[tuple[float, int]] = []
        b.attach(lambda data: arrivals.append((loop.time(), len(data))), lambda exc: None)  # type: ignore[union-attr]
        a.attach(lambda data: None, lambda exc: None)  # type: ignore[union-attr]
        a.send(bytes(1000))
        await asyncio.sleep(5)
        return arrivals

    arrivals = on_memory(main)
    assert sum(n for _, n in arrivals) == 1000
    assert arrivals[-1][0] == pytest.approx(1000 * 10 / 9600)
    assert arrivals[0][0] == pytest.approx(8 * 10 / 9600)  # the first piece, not all at once


def test_an_unknown_virtual_wire_is_a_clear_error() -> None:
    async def main() -> None:
        with pytest.raises(TransportClosed, match="no virtual wire virtual://nope/x"):
            open_transport("virtual://nope/x")

    on_memory(main)
