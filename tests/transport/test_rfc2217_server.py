"""A device's pty served over RFC 2217 (`transport.rfc2217_server`), opened by pyserial's client
as the lab's taps open it (`SerialTransport("rfc2217://...")`): binary-clean both ways (Telnet's
IAC byte 0xFF included), the device's new pty found after it restarts, and a client that comes
again replacing the one before."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from ktcs_bench.transport import PtyTransport, SerialTransport, Transport
from ktcs_bench.transport.rfc2217_server import Rfc2217Server

from .test_serialport import ALL_BYTES


def read_exactly(t: Transport, n: int, timeout: float = 5.0) -> bytes:
    """`n` bytes from `t` within `timeout` s (pyserial's RFC 2217 client hands them over a few
    at a time)."""
    got, end = b"", time.monotonic() + timeout
    while len(got) < n and time.monotonic() < end:
        got += t.recv(0.05)
    return got


@pytest.fixture
def device() -> Iterator[list[PtyTransport]]:
    """The device's pty (the list's last: a restart puts a new one there)."""
    ptys = [PtyTransport("device", line_rate=None)]
    yield ptys
    for p in ptys:
        p.close()


@pytest.fixture
def server(device: list[PtyTransport]) -> Iterator[Rfc2217Server]:
    srv = Rfc2217Server(("127.0.0.1", 0), lambda: device[-1].path, name="test")
    srv.start()
    yield srv
    srv.stop()


def url(server: Rfc2217Server) -> str:
    return f"rfc2217://{server.listen[0]}:{server.listen[1]}"


def test_a_pty_served_over_rfc2217_is_binary_clean_both_ways(
    device: list[PtyTransport], server: Rfc2217Server
) -> None:
    with SerialTransport(url(server), "tap", line_rate=None) as tap:
        tap.send(ALL_BYTES)  # 0xFF is Telnet's IAC: escaped on the wire, one byte on the line
        assert read_exactly(device[-1], len(ALL_BYTES)) == ALL_BYTES
        device[-1].send(ALL_BYTES[::-1])
        assert read_exactly(tap, len(ALL_BYTES)) == ALL_BYTES[::-1]
        status = server.status()
        assert status["open"] and status["path"] == device[-1].path and status["client"]


def test_a_restarted_device_and_a_new_client_are_served(
    device: list[PtyTransport], server: Rfc2217Server
) -> None:
    first = SerialTransport(url(server), "tap", line_rate=None)
    try:
        first.send(b"\x01\x02")
        assert read_exactly(device[-1], 2) == b"\x01\x02"
        device.append(PtyTransport("device again", line_rate=None))  # restarted on a new pty
        with SerialTransport(url(server), "tap again", line_rate=None) as second:
            got = b""
            for _ in range(100):  # the server moves to the new pty within its read timeout
                second.send(b"\xff\x10")
                got += device[-1].recv(0.1)
                if got:
                    break
            assert got.startswith(b"\xff\x10"), got
            device[-1].send(b"back")
            assert read_exactly(second, 4) == b"back"
            assert server.status()["connections"] == 2
    finally:
        first.close()
