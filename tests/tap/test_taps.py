"""Taps over real ptys (os.openpty + pyserial) and real TCP sockets on 127.0.0.1."""

from __future__ import annotations

import asyncio
import os
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import serial

from ktcs_bench.capture import open_writer, read_capture
from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.emulator.device import Device
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.faults import BitErrors, Delay, DropFrame
from ktcs_bench.runtime import read_token, server_token
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.transport import jsonlines

CODEC1 = FrameCodec(get_profile("ktcs-type1"))
CODEC2 = FrameCodec(get_profile("ktcs-type2"))


def wait_until(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        time.sleep(0.01)


def read_exactly(port: serial.Serial, n: int, timeout: float = 5.0) -> bytes:
    out = bytearray()
    end = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < end:
        out += port.read(n - len(out))
    return bytes(out)


@pytest.fixture
def pty_link() -> Iterator[tuple[PtyTap, serial.Serial, serial.Serial]]:
    tap = PtyTap(names=("ixl", "atc"), seed=7)
    with tap:
        a = serial.Serial(tap.paths["ixl"], 9600, timeout=0.2)
        b = serial.Serial(tap.paths["atc"], 9600, timeout=0.2)
        try:
            yield tap, a, b
        finally:
            a.close()
            b.close()


def test_pty_tap_forwards_both_directions_byte_exact_and_records(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    blob = bytes(range(256)) * 64  # every byte value, 16 KiB: raw mode, no line discipline
    a.write(blob)
    assert read_exactly(b, len(blob)) == blob
    fs = [CODEC1.encode(k, 1, bytes([1, 0, 2, 3])) for k in range(3)]
    b.write(b"".join(fs))
    assert read_exactly(a, sum(map(len, fs))) == b"".join(fs)
    wait_until(lambda: sum(r.direction == "atc>ixl" for r in tap.records()) == 3)
    back = [r for r in tap.records() if r.direction == "atc>ixl"]
    assert [r.data for r in back] == fs
    assert all(r.time is not None for r in back)
    sent = b"".join(r.data for r in tap.records() if r.direction == "ixl>atc")
    wait_until(lambda: b"".join(r.data for r in tap.records() if r.direction == "ixl>atc") == blob)
    assert sent == blob[: len(sent)]


def test_pty_tap_drop_frame_removes_exactly_one(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    fs = [CODEC1.encode(k, 3) for k in range(4)]
    tap.inject(DropFrame(direction="ixl>atc"))
    a.write(b"".join(fs))
    marker = CODEC1.encode(9, 3)
    a.write(marker)  # it passes, and nothing else of the four comes before it
    want = b"".join(fs[1:]) + marker
    assert read_exactly(b, len(want)) == want
    assert tap.status()["directions"]["ixl>atc"]["stats"]["frames_dropped"] == 1


def test_pty_tap_bit_errors_at_about_the_rate(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    tap.inject(BitErrors(0.01, direction="atc>ixl"))
    zeros = bytes(20_000)
    b.write(zeros)
    got = read_exactly(a, len(zeros))
    assert len(got) == len(zeros)
    flipped = sum(bin(x).count("1") for x in got)
    assert 0.8 * 1600 < flipped < 1.2 * 1600
    a.write(b"\x00" * 100)  # the other direction is untouched
    assert read_exactly(b, 100) == bytes(100)


def test_pty_tap_cut_stops_traffic_and_restore_resumes(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    tap.cut()
    a.write(b"lost")
    b.write(b"lost too")

    def dropped(direction: str) -> int:
        return int(tap.status()["directions"][direction]["stats"]["bytes_dropped"])

    wait_until(lambda: dropped("ixl>atc") == 4 and dropped("atc>ixl") == 8)  # the tap had them
    tap.restore()
    a.write(b"hello")
    b.write(b"world")
    assert read_exactly(b, 5) == b"hello" and read_exactly(a, 5) == b"world"  # nothing before


def test_control_port_commands_and_subscribe(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    assert tap.control_address is not None
    with TapClient(tap.control_address) as sub_client, TapClient(tap.control_address) as ctl:
        events = sub_client.subscribe(timeout=5)
        header = next(events)
        assert header["profile"] == "ktcs-type1" and header["names"] == ["ixl", "atc"]
        ctl.command("garbage ixl->atc 02 ff 00")
        assert read_exactly(b, 3) == b"\x02\xff\x00"
        frame = CODEC1.encode(9, 6)
        ctl.command(f"send atc->ixl {frame.hex()}")
        assert read_exactly(a, len(frame)) == frame
        seen = []
        for ev in events:
            seen.append(ev)
            if ev.get("direction") == "atc>ixl":
                break
        assert any(ev.get("command", "").startswith("garbage") for ev in seen)
        assert seen[-1]["hex"] == frame.hex() and isinstance(seen[-1]["time"], float)
        status = ctl.status()
        assert status["paths"] == tap.paths
        with pytest.raises(Exception, match="unknown command"):
            ctl.command("explode")


class EchoServer:
    """A TCP server on 127.0.0.1 that echoes what it gets (the tap's target)."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.address = self.sock.getsockname()[:2]
        self.conns: list[socket.socket] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            threading.Thread(target=self._echo, args=(conn,), daemon=True).start()

    @staticmethod
    def _echo(conn: socket.socket) -> None:
        with conn:
            while True:
                try:
                    data = conn.recv(65536)
                except OSError:
                    return
                if not data:
                    return
                conn.sendall(data)

    def close(self) -> None:
        self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        for c in self.conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self.thread.join(5)


def recv_exactly(sock: socket.socket, n: int) -> bytes:
    out = bytearray()
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            break
        out += chunk
    return bytes(out)


@pytest.fixture
def echo() -> Iterator[EchoServer]:
    server = EchoServer()
    yield server
    server.close()


def test_tcp_tap_forwards_records_and_writes_pcapng(echo: EchoServer, tmp_path: Path) -> None:
    path = tmp_path / "t2.pcapng"
    writer = open_writer(path, link="type2")
    with TcpTap(("127.0.0.1", 0), echo.address, names=("ixl", "ctc"), writers=[writer]) as tap:
        assert isinstance(tap, TcpTap) and tap.listen_address is not None
        fs = [CODEC2.encode(k, 0x40, b"", 0) for k in range(3)]
        with socket.create_connection(tap.listen_address, timeout=5) as s:
            s.sendall(b"".join(fs))
            assert recv_exactly(s, sum(map(len, fs))) == b"".join(fs)
            wait_until(lambda: len(tap.records()) == 6)
        dirs = [r.direction for r in tap.records()]
        assert dirs.count("ixl>ctc") == 3 and dirs.count("ctc>ixl") == 3
        assert [r.data for r in tap.records() if r.direction == "ctc>ixl"] == fs
    cap = read_capture(path)
    assert [r.data for r in cap.records if r.direction == "ixl>ctc"] == fs


def test_tcp_tap_cut_closes_and_refuses_restore_reconnects(echo: EchoServer) -> None:
    with TcpTap(("127.0.0.1", 0), echo.address) as tap:
        assert isinstance(tap, TcpTap) and tap.listen_address is not None
        s = socket.create_connection(tap.listen_address, timeout=5)
        s.sendall(b"ping")
        assert recv_exactly(s, 4) == b"ping"
        tap.cut()
        assert s.recv(10) == b""  # the tap closed the connection
        s.close()
        with socket.create_connection(tap.listen_address, timeout=5) as s2:
            assert s2.recv(10) == b""  # refused while cut
        tap.restore()
        with socket.create_connection(tap.listen_address, timeout=5) as s3:
            s3.sendall(b"again")
            assert recv_exactly(s3, 5) == b"again"


def test_tcp_tap_delayed_bytes_die_with_their_connection(echo: EchoServer) -> None:
    """A delayed chunk of a connection that closes is never delivered on the next one."""
    with TcpTap(("127.0.0.1", 0), echo.address) as tap:
        assert isinstance(tap, TcpTap) and tap.listen_address is not None

        def stats() -> dict[str, int]:
            return tap.status()["directions"]["a>b"]["stats"]  # type: ignore[no-any-return]

        # held far longer than the connection lives, however slow the machine
        tap.inject(Delay(30.0, direction="a>b"))
        with socket.create_connection(tap.listen_address, timeout=5) as s:
            wait_until(lambda: tap.connected)
            s.sendall(b"stale")
            wait_until(lambda: stats()["bytes_in"] == 5)
        wait_until(lambda: not tap.connected)
        # the signal: the tap let go of the 5 delayed bytes with their connection
        wait_until(lambda: stats()["bytes_dropped"] == 5)
        tap.clear()
        with socket.create_connection(tap.listen_address, timeout=5) as s2:
            s2.sendall(b"fresh")
            assert recv_exactly(s2, 5) == b"fresh"
        # toward the server the tap delivered the 5 fresh bytes and nothing else, ever
        assert stats()["bytes_out"] == 5


def test_client_refuses_what_is_not_a_tap(echo: EchoServer) -> None:
    """An echo server repeats `status` back: a clear PeerError, not a JSON traceback."""
    with pytest.raises(PeerError, match="not a tap's control"), TapClient(echo.address) as client:
        client.status()


def test_tap_creation_failure_leaves_nothing_open() -> None:
    busy = socket.create_server(("127.0.0.1", 0))
    try:
        tap = TcpTap(busy.getsockname()[:2], ("127.0.0.1", 9))
        with pytest.raises(Exception, match="cannot open"):
            tap.start()
    finally:
        busy.close()
    assert os.path.exists("/proc/self/fd")


def test_tcp_tap_pcapng_carries_the_real_addresses_of_both_ends(
    echo: EchoServer, tmp_path: Path
) -> None:
    """Read back by tshark: each packet goes between the address the station connected from and
    the target's address, both ways -- not addresses made up for the capture."""
    path = tmp_path / "t2.pcapng"
    with TcpTap(("127.0.0.1", 0), echo.address, names=("ixl", "ctc"),
                writers=[open_writer(path, link="type2")]) as tap:  # fmt: skip
        assert isinstance(tap, TcpTap) and tap.listen_address is not None
        fs = [CODEC2.encode(k, 0x40, b"", 0) for k in range(2)]
        with socket.create_connection(tap.listen_address, timeout=5) as s:
            station = s.getsockname()[:2]
            s.sendall(b"".join(fs))
            assert recv_exactly(s, sum(map(len, fs))) == b"".join(fs)
            wait_until(lambda: len(tap.records()) == 4)
    tshark = shutil.which("tshark")
    assert tshark is not None, "tshark is not installed (Debian: apt-get install -y tshark)"
    home = tmp_path / "home"
    home.mkdir()
    done = subprocess.run(
        [tshark, "-r", str(path), "-T", "fields", "-e", "ip.src", "-e", "tcp.srcport",
         "-e", "ip.dst", "-e", "tcp.dstport", "-e", "frame.comment"],
        capture_output=True, text=True, timeout=120, env={**os.environ, "HOME": str(home)},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = [line.split("\t") for line in done.stdout.splitlines()]
    ends = {"ixl": (station[0], str(station[1])), "ctc": (echo.address[0], str(echo.address[1]))}
    assert len(rows) == 4
    for src, sport, dst, dport, comment in rows:
        a, b = comment.split(">")
        assert ((src, sport), (dst, dport)) == (ends[a], ends[b]), comment


def test_control_port_speaks_the_devices_json_lines(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    """The request helper the bench uses for every device's control port works on a tap's, the
    token check included: nothing is acted on before the token; a bad line is answered and the
    connection goes on."""
    tap, a, b = pty_link
    assert tap.control_address is not None
    host, port = tap.control_address
    token = read_token(tap.token_file)

    async def talk() -> list[dict[str, object]]:
        answers = [await jsonlines.request(host, port, {"cmd": "status"}, token=token)]
        answers.append(await jsonlines.request(
            host, port, {"cmd": "ber", "rate": 0.5, "direction": "atc>ixl"}, token=token))  # fmt: skip
        peer = await jsonlines.connect(host, port)
        try:
            for obj in ({"cmd": "clear"}, {"cmd": "clear", "token": "0" * 64}, {"token": token}):
                peer.send(obj)
                answers.append(await peer.read() or {})
            answers.append(await jsonlines.request(host, port, {"cmd": "status"}, token=token))
            for line in (b"not json\n", b'{"cmd": "explode"}\n', b'{"cmd": "clear"}\n'):
                peer.writer.write(line)
                answers.append(await peer.read() or {})
        finally:
            peer.close()
        return answers

    status, ber, before, wrong, admitted, then, bad, unknown, clear = asyncio.run(talk())
    assert status["ok"] is True and isinstance(status["status"], dict)
    assert status["status"]["paths"] == tap.paths
    assert ber == {"ok": True, "command": "ber 0.5 atc>ixl"}
    assert before["refused"] is True and wrong["refused"] is True and admitted == {"ok": True}
    assert then["status"]["directions"]["atc>ixl"]["ber"] == 0.5  # the refused clears did nothing
    assert "error" in bad and unknown["ok"] is False and "unknown command" in str(unknown["error"])
    assert clear == {"ok": True, "command": "clear"}
    assert tap.status()["directions"]["atc>ixl"]["ber"] == 0.0


def test_a_subscriber_that_leaves_is_dropped(
    pty_link: tuple[PtyTap, serial.Serial, serial.Serial],
) -> None:
    tap, a, b = pty_link
    assert tap.control_address is not None
    with TapClient(tap.control_address) as ctl:
        sub = TapClient(tap.control_address)
        next(sub.subscribe())
        wait_until(lambda: ctl.status()["subscribers"] == 1)
        sub.close()
        wait_until(lambda: ctl.status()["subscribers"] == 0)


def test_client_refuses_a_devices_control_port() -> None:
    """A device answers `status` too, but it is not a tap: a clear PeerError."""
    ready = threading.Event()
    box: dict[str, object] = {}

    def serve() -> None:
        async def main() -> None:
            device = Device("atc18")
            device.token = server_token()[0]  # the user's, as a device started alone has
            await device.start()
            box["address"], box["stop"] = device.ready_info["control"], asyncio.Event()
            box["loop"] = asyncio.get_running_loop()
            ready.set()
            await box["stop"].wait()  # type: ignore[attr-defined]
            await device.close()

        asyncio.run(main())

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        assert ready.wait(10)
        host, _, port = str(box["address"]).rpartition(":")
        with TapClient((host, int(port))) as client:
            with pytest.raises(PeerError, match="not a tap's control"):
                client.status()
            with pytest.raises(UsageError, match="unknown command"):
                client.command("ber 1e-3")
    finally:
        loop = box.get("loop")
        if isinstance(loop, asyncio.AbstractEventLoop):
            loop.call_soon_threadsafe(box["stop"].set)  # type: ignore[attr-defined]
        thread.join(10)
