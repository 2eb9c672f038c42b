"""A tap end that is a real device's serial line (`PtyTap(external=...)`): the tap opens the
endpoint itself -- here `socket://`, a pyserial URL to a real TCP server standing in for a serial
server across the network -- paces what it writes there, and reopens it when it goes away."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

import serial

from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.tap.pty import PtyTap

CODEC = FrameCodec(get_profile("ktcs-type1"))


def wait_until(cond: Callable[[], object], timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        time.sleep(0.01)


def recv_exactly(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        assert chunk, "closed early"
        out += chunk
    return out


def read_exactly(port: serial.Serial, n: int) -> bytes:
    out = b""
    end = time.monotonic() + 10
    while len(out) < n and time.monotonic() < end:
        out += port.read(n - len(out))
    return out


def end_state(tap: PtyTap) -> dict[str, object]:
    return tap.status()["external_ends"]["atc"]  # type: ignore[no-any-return]


def test_an_external_end_carries_the_link_and_is_reopened_when_it_comes_back() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    server.settimeout(10)
    frame = CODEC.encode_message(1, "LINK_TEST")
    with PtyTap(names=("ixl", "atc"), external={"atc": f"socket://127.0.0.1:{port}"},
                line_rate=9600, control=None) as tap:  # fmt: skip
        assert set(tap.paths) == {"ixl"} and tap.external == {"atc": f"socket://127.0.0.1:{port}"}
        device, _ = server.accept()  # the tap connected to the "serial server" at start
        ixl = serial.Serial(tap.paths["ixl"], timeout=0.2)
        try:
            assert end_state(tap)["open"] and end_state(tap)["opens"] == 1
            start = time.monotonic()
            for _ in range(4):
                ixl.write(frame)
            assert recv_exactly(device, 4 * len(frame)) == 4 * frame
            # written at the line rate: 4 frames of 10-bit bytes at 9600 bit/s take this long
            assert time.monotonic() - start >= 0.9 * 4 * len(frame) * 10 / 9600
            device.sendall(frame)
            assert read_exactly(ixl, len(frame)) == frame
            # the device goes away: the end is closed, what is sent to it meanwhile is lost
            device.close()
            wait_until(lambda: not end_state(tap)["open"])
            ixl.write(frame)
            wait_until(lambda: end_state(tap)["dropped"] == len(frame))
            # it comes back at the same address: the tap reopens it and the link carries again
            device, _ = server.accept()
            wait_until(lambda: end_state(tap)["open"] and end_state(tap)["opens"] == 2)
            ixl.write(frame)
            assert recv_exactly(device, len(frame)) == frame
        finally:
            ixl.close()
            device.close()
    server.close()


def test_an_external_end_not_there_at_start_is_opened_when_it_appears() -> None:
    holder = socket.create_server(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    holder.close()  # nothing listens there yet
    with PtyTap(names=("ixl", "atc"), external={"atc": f"socket://127.0.0.1:{port}"},
                line_rate=None, control=None) as tap:  # fmt: skip
        state = end_state(tap)
        assert not state["open"] and "refused" in str(state["error"]).lower(), state
        server = socket.create_server(("127.0.0.1", port))
        server.settimeout(10)
        device, _ = server.accept()
        wait_until(lambda: end_state(tap)["open"])
        device.close()
        server.close()
