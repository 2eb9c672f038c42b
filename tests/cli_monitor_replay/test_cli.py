"""The CLI as a user runs it: real subprocesses, real ptys (pyserial) and TCP on 127.0.0.1."""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from ktcs_bench.capture import CaptureRecord, open_writer, read_capture
from ktcs_bench.codec import FrameCodec, get_profile

CLI = [sys.executable, "-m", "ktcs_bench.cli.main"]
C1 = FrameCodec(get_profile("ktcs-type1"))
C2 = FrameCodec(get_profile("ktcs-type2"))
REQ = bytes.fromhex("02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03")
ACK = bytes.fromhex("02 00 00 10 06 00 03 87 00 00 03")


@pytest.fixture
def env(tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp_path / "run"), "NO_COLOR": "1"}


def cli(*args: str, env: dict[str, str], timeout: float = 30) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, env=env, timeout=timeout)


@pytest.fixture
def tap_process(tmp_path: Path, env: dict[str, str]) -> Iterator[tuple[dict[str, object], Path]]:
    proc = subprocess.Popen(
        [*CLI, "tap", "run", "--pty", "--names", "ixl,atc", "--name", "t1", "--json",
         "--write", str(tmp_path / "t1.hex"), "--write", str(tmp_path / "t1.pcapng")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 20)
        assert ready, "the tap did not print its info"
        info = json.loads(proc.stdout.readline())
        yield info, tmp_path
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=10)
        assert proc.returncode == 0, err


def read_exactly(port: serial.Serial, n: int, timeout: float = 5.0) -> bytes:
    out = bytearray()
    end = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < end:
        out += port.read(n - len(out))
    return bytes(out)


def test_tap_cli_monitor_faults_and_captures(
    tap_process: tuple[dict[str, object], Path], env: dict[str, str]
) -> None:
    info, tmp = tap_process
    paths = info["paths"]
    assert isinstance(paths, dict)
    link = C1.encode(0x11, 3)
    with (
        serial.Serial(paths["ixl"], timeout=0.2) as a,
        serial.Serial(paths["atc"], timeout=0.2) as b,
    ):
        a.write(REQ)
        assert read_exactly(b, len(REQ)) == REQ
        b.write(ACK)
        assert read_exactly(a, len(ACK)) == ACK
        a.write(link + link)  # the same SEQ twice: a retransmission
        assert read_exactly(b, 2 * len(link)) == link + link
        mon = cli("monitor", "t1", "--history", "--count", "4", "--timeout", "20", env=env)
        assert mon.returncode == 0, mon.stderr
        assert "REQUEST_ALL" in mon.stdout and "CRC OK" in mon.stdout
        assert "Packet = [83]-[7B], Cal = [83]-[7B]" in mon.stdout
        assert "[02][04][00][10]" in mon.stdout
        assert "ARQ: ACK of SEQ 0x10" in mon.stdout
        assert "ARQ: retransmission of SEQ 0x11 (transmission 2)" in mon.stdout
        js = cli("monitor", "t1", "--history", "--json", "--count", "1", "--timeout", "20", env=env)
        first = json.loads(js.stdout.splitlines()[0])
        assert first["direction"] == "ixl>atc" and first["op_name"] == "REQUEST_ALL"
        assert first["crc_ok"] is True and isinstance(first["time"], float)

        out = cli("tap", "fault", "t1", "drop-frame", "ixl->atc", env=env)
        assert out.returncode == 0 and "drop-frame" in out.stdout, out.stderr
        a.write(REQ + link)
        assert read_exactly(b, len(link)) == link  # REQ was dropped, exactly one frame
        out = cli("tap", "fault", "t1", "cut", env=env)
        assert out.returncode == 0

        def dropped() -> int:
            status = json.loads(cli("tap", "status", "t1", env=env).stdout)
            return int(status["directions"]["ixl>atc"]["stats"]["bytes_dropped"])

        before = dropped()
        a.write(REQ)
        deadline = time.monotonic() + 10
        while dropped() < before + len(REQ):  # the tap had it, and threw it away
            assert time.monotonic() < deadline, "the tap never saw the REQ sent while cut"
        assert cli("tap", "fault", "t1", "restore", env=env).returncode == 0
        marker = C1.encode(0x12, 3)
        a.write(marker)
        # nothing dropped or cut comes before it (nor anything more of the earlier frames)
        assert read_exactly(b, len(marker)) == marker
        bad = cli("tap", "fault", "t1", "explode", env=env)
        assert bad.returncode == 2 and "unknown command" in bad.stderr
        status = json.loads(cli("tap", "status", "t1", env=env).stdout)
        assert status["directions"]["ixl>atc"]["stats"]["frames_dropped"] == 1
        # the recorded hex log decodes while the tap runs
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            dec = cli("decode", str(tmp / "t1.hex"), "--profile", "ktcs-type1", env=env)
            if "6 frames, 6 good" in dec.stdout:
                break
            time.sleep(0.1)
        assert "6 frames, 6 good" in dec.stdout, dec.stdout[-500:]
        assert "ixl>atc" in dec.stdout and "atc>ixl" in dec.stdout
    cap = read_capture(tmp / "t1.pcapng")
    assert [r.data for r in cap.records][:3] == [REQ, ACK, link]
    tshark = shutil.which("tshark")
    if tshark is None:
        pytest.fail("tshark is not installed (Debian: apt-get install -y tshark)")
    rows = subprocess.run(
        [tshark, "-r", str(tmp / "t1.pcapng"), "-T", "fields", "-e", "frame.interface_name",
         "-e", "data.data"], capture_output=True, text=True, timeout=60,
    ).stdout.splitlines()  # fmt: skip
    assert len(rows) == len(cap.records) == 6
    assert rows[0].split("\t") == ["ixl>atc", REQ.hex()]


def test_monitor_reads_a_capture_file(tmp_path: Path, env: dict[str, str]) -> None:
    path = tmp_path / "c.hex"
    nak = C1.encode(0x11, 0x15, b"\x01")
    with open_writer(path, profile="ktcs-type1") as w:
        for k, (d, f) in enumerate([("ixl>atc", REQ), ("atc>ixl", nak), ("ixl>atc", REQ)]):
            w.write(CaptureRecord(100.0 + k, d, f))
    out = cli("monitor", str(path), env=env)
    assert out.returncode == 0, out.stderr
    assert "ARQ: NAK reason 1 (crc error) for SEQ 0x11" in out.stdout
    assert "ARQ: retransmission of SEQ 0x10 (transmission 2)" in out.stdout


class PtyEcho:
    """A peer on a pty that echoes every byte back (the device under test, in miniature)."""

    def __init__(self, mangle: bool = False) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.mangle = mangle
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.05)
            if ready:
                data = os.read(self.master, 4096)
                if self.mangle:
                    data = data.replace(b"\x11", b"\x12")
                os.write(self.master, data)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def echo_pty() -> Iterator[PtyEcho]:
    peer = PtyEcho()
    yield peer
    peer.close()


def _requests(tmp: Path) -> tuple[Path, Path, list[bytes]]:
    frames = [REQ, C1.encode(0x11, 3), C1.encode(0x12, 2, bytes([3, 0, 1]))]
    req, exp = tmp / "req.hex", tmp / "expect.hex"
    with open_writer(req, profile="ktcs-type1") as w:
        for k, f in enumerate(frames):
            w.write(CaptureRecord(10.0 + 0.05 * k, "ixl>atc", f))
    with open_writer(exp, profile="ktcs-type1") as w:
        for k, f in enumerate(frames):
            w.write(CaptureRecord(10.0 + 0.05 * k, "atc>ixl", f))
    return req, exp, frames


@pytest.mark.parametrize("timing", ["line", "original", "step"])
def test_replay_into_a_pty_expect_passes(
    echo_pty: PtyEcho, tmp_path: Path, env: dict[str, str], timing: str
) -> None:
    req, exp, frames = _requests(tmp_path)
    rec = tmp_path / "got.hex"
    out = cli("replay", str(req), "--to", echo_pty.path, "--timing", timing, "--wait", "0.3",
              "--expect", str(exp), "--record", str(rec), env=env)  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert "3 replies match" in out.stdout
    got = read_capture(rec)
    assert [r.data for r in got.records if r.direction == "atc>ixl"] == frames
    assert [r.data for r in got.records if r.direction == "ixl>atc"] == frames
    # the recording is itself a valid expectation
    again = cli("replay", str(req), "--to", echo_pty.path, "--wait", "0.3", "--quiet",
                "--expect", str(rec), env=env)  # fmt: skip
    assert again.returncode == 0, again.stderr


def test_replay_expect_exits_1_on_a_difference(tmp_path: Path, env: dict[str, str]) -> None:
    peer = PtyEcho(mangle=True)  # answers SEQ 0x11 as 0x12
    try:
        req, exp, _ = _requests(tmp_path)
        out = cli("replay", str(req), "--to", peer.path, "--wait", "0.3", "--expect", str(exp),
                  env=env)  # fmt: skip
    finally:
        peer.close()
    assert out.returncode == 1
    assert "reply frame 2 differs" in out.stderr
    assert "expected 02 00 00 11" in out.stderr and "got      02 00 00 12" in out.stderr


def test_replay_over_tcp_and_into_a_tap(tmp_path: Path, env: dict[str, str]) -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def echo_once() -> None:
        conn, _ = server.accept()
        with conn:
            while data := conn.recv(4096):
                conn.sendall(data)

    t = threading.Thread(target=echo_once, daemon=True)
    t.start()
    frames = [C2.encode(k, 0x40, b"", 0) for k in range(3)]
    req = tmp_path / "t2.hex"
    with open_writer(req, profile="ktcs-type2", link="type2") as w:
        for k, f in enumerate(frames):
            w.write(CaptureRecord(float(k), "ixl>ctc", f))
    try:
        out = cli("replay", str(req), "--to", f"tcp://127.0.0.1:{port}", "--wait", "0.3",
                  "--json", env=env)  # fmt: skip
    finally:
        t.join(10)
        server.close()
    assert out.returncode == 0, out.stderr
    rows = [json.loads(x) for x in out.stdout.splitlines()]
    assert [r["direction"] for r in rows].count("ctc>ixl") == 3
    assert all(r["op_name"] == "HEARTBEAT" and r["crc_ok"] for r in rows)

    # the same frames into a tap whose end b is a pty echo
    from ktcs_bench.tap.pty import PtyTap

    with PtyTap(names=("ixl", "atc")) as tap:
        assert isinstance(tap, PtyTap) and tap.control_address is not None
        with serial.Serial(tap.paths["atc"], timeout=0.05) as dev:
            stop = threading.Event()

            def echo_dev() -> None:
                while not stop.is_set():
                    data = dev.read(4096)
                    if data:
                        dev.write(data)

            th = threading.Thread(target=echo_dev, daemon=True)
            th.start()
            req1, exp1, _ = _requests(tmp_path)
            host, cport = tap.control_address
            try:
                out = cli("replay", str(req1), "--to", f"tap://{host}:{cport}", "--wait", "0.3",
                          "--expect", str(exp1),
                          env={**env, "KTCS_BENCH_TOKEN_FILE": str(tap.token_file)})  # fmt: skip
            finally:
                stop.set()
                th.join(5)
        assert out.returncode == 0, out.stdout + out.stderr
        assert sum(r.direction == "atc>ixl" for r in tap.records()) == 3


def test_replay_original_timing_caps_long_silences_with_max_gap(
    echo_pty: PtyEcho, tmp_path: Path, env: dict[str, str]
) -> None:
    """A capture with a 100 s silence replays with it cut to --max-gap, shorter gaps kept: the
    replay ends well inside the 30 s the CLI is given (it would take 100 s uncapped), and the
    recording shows each gap at least as long as the capped schedule says."""
    frames = [C1.encode(0x20 + k, 3) for k in range(4)]
    times = [10.0, 10.15, 110.15, 110.25]  # the third frame comes after 100 s of silence
    req, exp, rec = tmp_path / "req.hex", tmp_path / "exp.hex", tmp_path / "got.hex"
    with open_writer(req, profile="ktcs-type1") as w, open_writer(exp, profile="ktcs-type1") as e:
        for t, f in zip(times, frames, strict=True):
            w.write(CaptureRecord(t, "ixl>atc", f))
            e.write(CaptureRecord(t, "atc>ixl", f))
    out = cli("replay", str(req), "--to", echo_pty.path, "--timing", "original", "--max-gap",
              "0.3", "--wait", "0.3", "--expect", str(exp), "--record", str(rec), env=env)  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert "4 replies match" in out.stdout
    sent = [r.time for r in read_capture(rec).records if r.direction == "ixl>atc"]
    assert len(sent) == 4 and all(t is not None for t in sent)
    gaps = [b - a for a, b in zip(sent, sent[1:], strict=False)]  # type: ignore[operator]
    assert gaps[0] >= 0.15 - 0.002 and gaps[1] >= 0.3 - 0.002 and gaps[2] >= 0.1 - 0.002, gaps


def test_replay_max_gap_goes_with_original_timing(tmp_path: Path, env: dict[str, str]) -> None:
    req, _, _ = _requests(tmp_path)
    out = cli("replay", str(req), "--to", "loop://", "--max-gap", "1", env=env)
    assert out.returncode == 2 and "--timing original" in out.stderr


def test_replay_refuses_a_binary_file_that_is_not_a_capture(
    tmp_path: Path, env: dict[str, str]
) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        binary = tmp_path / "firmware.bin"
        binary.write_bytes(Path(sys.executable).read_bytes()[:200_000])
        out = cli("replay", str(binary), "--to", os.ttyname(slave), env=env)
        assert out.returncode == 2, out.stdout + out.stderr
        assert "is not a capture" in out.stderr and "Traceback" not in out.stderr
        # the replay has exited: anything it had sent would be waiting on the pty now
        os.set_blocking(master, False)
        with pytest.raises(BlockingIOError):
            os.read(master, 4096)
    finally:
        os.close(master)
        os.close(slave)
