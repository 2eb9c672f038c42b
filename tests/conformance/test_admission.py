"""Admission to Type II (SPEC §10) with the real processes over real sockets: 127.0.0.1 by
default, a source-address allow-list, TLS with client certificates (profile type2-tls), and
refusals logged with the peer's address."""

from __future__ import annotations

import asyncio
import re
import shutil
import socket
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.transport import jsonlines

from .conftest import Proc, cli, free_port

T2 = FrameCodec(get_profile("ktcs-type2"))


def _ident_answer(address: str, station: int = 18) -> bytes:
    """Connect, send IDENT, return what comes back before the CTC closes (or 2 s pass)."""
    host, _, port = address.rpartition(":")
    data = b""
    with socket.create_connection((host, int(port)), timeout=2.0) as s:
        s.sendall(T2.encode_message(0, "IDENT", 0, station=station, version=1))
        try:
            while chunk := s.recv(4096):
                data += chunk
                if len(data) >= 10:
                    break
        except (TimeoutError, ConnectionError):
            pass
    return data


def _wait_log(proc: Proc, text: str, timeout: float = 5.0) -> str:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        log = proc.stderr()
        if text in log:
            return log
        time.sleep(0.1)
    return proc.stderr()


def _tls_refusals(proc: Proc, at_least: int, timeout: float = 5.0) -> list[str]:
    """The reasons of the CTC's logged TLS refusals of 127.0.0.1, once there are `at_least`."""
    end = time.monotonic() + timeout
    while True:
        found = re.findall(r"refused 127\.0\.0\.1:\d+: TLS handshake failed: (.+)", proc.stderr())
        if len(found) >= at_least or time.monotonic() >= end:
            return found
        time.sleep(0.1)


def test_binds_loopback_and_source_allow_list(spawn: Callable[..., Proc]) -> None:
    ctc = spawn("emulator", "ctc")
    assert ctc.ready["listen"].startswith("127.0.0.1:")  # loopback unless told otherwise
    closed = spawn("emulator", "ctc", "--listen", "127.0.0.1:0", "--allow-source", "10.9.9.0/24")
    assert _ident_answer(closed.ready["listen"]) == b""  # dropped at accept, before any byte
    log = _wait_log(closed, "refused 127.0.0.1:")
    assert "refused 127.0.0.1:" in log and "source address 127.0.0.1 is not allowed" in log
    opened = spawn("emulator", "ctc", "--listen", "127.0.0.1:0", "--allow-source", "127.0.0.0/8")
    run = cli("conformance", "--role", "ctc", "--target", f"tcp://{opened.ready['listen']}",
              "--station", "18", "--case", "t2-ident", "--case", "t2-refused-station")  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    log = _wait_log(opened, "station 65000 is not configured")
    assert "refused 127.0.0.1:" in log and "station 65000 is not configured" in log


def _openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True)


def _certs(folder: Path) -> dict[str, Path]:
    """A CA, the CTC's and an IXL's certificates signed by it, and a stranger's self-signed one."""
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    f = {n: folder / n for n in ("ca.pem", "ca.key", "san.ext")}
    f["san.ext"].write_text("subjectAltName=IP:127.0.0.1\n")
    _openssl("req", "-x509", *ec, "-days", "1", "-subj", "/CN=ktcs-lab-ca",
             "-keyout", str(f["ca.key"]), "-out", str(f["ca.pem"]))  # fmt: skip
    for name in ("ctc", "ixl18"):
        key, csr, pem = folder / f"{name}.key", folder / f"{name}.csr", folder / f"{name}.pem"
        _openssl("req", *ec, "-subj", f"/CN={name}", "-keyout", str(key), "-out", str(csr))
        _openssl("x509", "-req", "-in", str(csr), "-CA", str(f["ca.pem"]), "-CAkey",
                 str(f["ca.key"]), "-CAcreateserial", "-days", "1", "-extfile",
                 str(f["san.ext"]), "-out", str(pem))  # fmt: skip
        f[f"{name}.pem"], f[f"{name}.key"] = pem, key
    f["stranger.pem"], f["stranger.key"] = folder / "stranger.pem", folder / "stranger.key"
    _openssl("req", "-x509", *ec, "-days", "1", "-subj", "/CN=stranger",
             "-addext", "subjectAltName=IP:127.0.0.1",
             "-keyout", str(f["stranger.key"]), "-out", str(f["stranger.pem"]))  # fmt: skip
    return f


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl tool")
def test_type2_tls_client_certificates(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    c = _certs(tmp_path)
    ctc = spawn("emulator", "ctc", "--listen", "127.0.0.1:0", "--tls-cert", str(c["ctc.pem"]),
                "--tls-key", str(c["ctc.key"]), "--tls-ca", str(c["ca.pem"]))  # fmt: skip
    address = ctc.ready["listen"]
    # our IXL with a certificate from the lab CA: admitted, full state at the CTC
    spawn("emulator", "ixl", "--station", "18", "--link", f"ctc=tcp://{address}",
          "--tls-cert", str(c["ixl18.pem"]), "--tls-key", str(c["ixl18.key"]),
          "--tls-ca", str(c["ca.pem"]), "--tls-server-name", "127.0.0.1")  # fmt: skip
    host, _, port = ctc.ready["control"].rpartition(":")

    def synced() -> bool:
        got = asyncio.run(jsonlines.request(host, int(port), {"cmd": "show", "station": 18}))
        return bool(got["summary"]["synced"])

    end = time.monotonic() + 15
    while not synced():
        assert time.monotonic() < end, ctc.stderr()
        time.sleep(0.2)
    assert _tls_refusals(ctc, 0, timeout=0) == []
    # plain TCP gets nothing, and the CTC logs the refusal with the peer's address
    assert _ident_answer(address, 20) == b""
    refusals = _tls_refusals(ctc, 1)
    assert len(refusals) == 1, ctc.stderr()
    # a stranger's certificate is not admitted, and that is logged too
    tls = ["--profile", "type2-tls", "--tls-ca", str(c["ca.pem"]), "--case", "t2-ident"]
    stranger = cli("conformance", "--role", "ctc", "--target", f"tcp://{address}", "--station",
                   "20", "--tls-cert", str(c["stranger.pem"]), "--tls-key",
                   str(c["stranger.key"]), *tls)  # fmt: skip
    # TLS 1.3: the CTC rejects the certificate after the client's side of the handshake, so the
    # suite sees the connection closed (no IDENT answer) rather than a handshake error; the CTC
    # sees the handshake fail and logs "refused 127.0.0.1:PORT: TLS handshake failed: ..."
    assert stranger.returncode in (1, 3), stranger.stdout + stranger.stderr
    assert "closed" in stranger.stdout or "SSL" in stranger.stdout
    refusals = _tls_refusals(ctc, 2)
    assert len(refusals) >= 2, ctc.stderr()
    assert all("certificate" in r for r in refusals[1:]), refusals
    good = cli("conformance", "--role", "ctc", "--target", f"tcp://{address}", "--station", "20",
               "--tls-cert", str(c["ixl18.pem"]), "--tls-key", str(c["ixl18.key"]), *tls)  # fmt: skip
    assert good.returncode == 0, good.stdout + good.stderr
    # the suite as a TLS CTC, our IXL connecting to it with its certificate
    port2 = free_port()
    suite = spawn("conformance", "--role", "ixl", "--target", f"listen://127.0.0.1:{port2}",
                  "--station", "18", "--tls-cert", str(c["ctc.pem"]), "--tls-key",
                  str(c["ctc.key"]), *tls[:-2], "--case", "t2-full-dump", wait=False)  # fmt: skip
    spawn("emulator", "ixl", "--station", "18", "--link", f"ctc=tcp://127.0.0.1:{port2}",
          "--tls-cert", str(c["ixl18.pem"]), "--tls-key", str(c["ixl18.key"]),
          "--tls-ca", str(c["ca.pem"]), "--tls-server-name", "127.0.0.1")  # fmt: skip
    assert suite.p.wait(30) == 0, suite.stderr()
