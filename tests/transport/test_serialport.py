"""Transports over real ptys and pyserial URLs: binary-clean, in order, both directions, no leaks."""

from __future__ import annotations

import socket
import threading

import pytest

from ktcs_bench.transport import (
    PtyTransport,
    SerialTransport,
    Transport,
    TransportClosed,
    open_transport,
)

ALL_BYTES = bytes(range(256)) * 2


def read_exactly(t: Transport, n: int, timeout: float = 5.0) -> bytes:
    got = b""
    for _ in range(int(timeout / 0.05)):
        got += t.recv(0.05)
        if len(got) >= n:
            break
    return got


@pytest.mark.parametrize("rate", [None, 96000.0])
def test_pty_pair_is_binary_clean_both_ways(rate: float | None) -> None:
    with PtyTransport("m", line_rate=rate) as m, SerialTransport(m.path, "s", line_rate=rate) as s:
        assert isinstance(m, Transport) and isinstance(s, Transport)
        m.send(ALL_BYTES)  # includes 0x03 (^C), 0x11/0x13 (XON/XOFF), 0x0D/0x0A
        assert read_exactly(s, len(ALL_BYTES)) == ALL_BYTES
        s.send(ALL_BYTES[::-1])
        assert read_exactly(m, len(ALL_BYTES)) == ALL_BYTES[::-1]
        assert m.drain(5.0) and s.drain(5.0)


def test_paced_writes_arrive_in_order_in_many_sends() -> None:
    with PtyTransport("m", line_rate=96000.0) as m, SerialTransport(m.path, "s") as s:
        chunks = [bytes([i]) * (i % 7 + 1) for i in range(100)]
        for c in chunks:
            m.send(c)
        assert read_exactly(s, sum(map(len, chunks))) == b"".join(chunks)


def test_loop_url() -> None:
    with SerialTransport("loop://", line_rate=None) as t:
        assert t.fileno() is None
        t.send(b"\x02hello\x03")
        assert read_exactly(t, 7) == b"\x02hello\x03"


def test_socket_url() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    accepted: list[socket.socket] = []
    thread = threading.Thread(target=lambda: accepted.append(server.accept()[0]))
    thread.start()
    try:
        with open_transport(f"socket://127.0.0.1:{port}", "sock", line_rate=None) as t:
            thread.join(5.0)
            (conn,) = accepted
            with conn:
                t.send(ALL_BYTES)
                got = b""
                while len(got) < len(ALL_BYTES):
                    got += conn.recv(4096)
                assert got == ALL_BYTES
                conn.sendall(b"back")
                assert read_exactly(t, 4) == b"back"
    finally:
        server.close()


def test_open_transport_pty_and_errors() -> None:
    with open_transport("pty", "lab-link") as t:
        assert isinstance(t, PtyTransport) and t.path.startswith("/dev/")
    with pytest.raises(TransportClosed):
        t.recv(0)
    with pytest.raises(TransportClosed):
        t.send(b"x")
    with pytest.raises(TransportClosed):
        open_transport("/dev/no-such-serial-port")
