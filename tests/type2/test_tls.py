"""Type II wrapped in TLS with client certificates (profile type2-tls, SPEC §10), on 127.0.0.1."""

from __future__ import annotations

import shutil
import ssl
import subprocess
from pathlib import Path

import pytest

from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.transport.ixl_client import IxlClient, StateTable

from .netutil import run

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl tool")


def self_signed(folder: Path, name: str) -> tuple[Path, Path]:
    cert, key = folder / f"{name}.pem", folder / f"{name}.key"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
         "-nodes", "-days", "1", "-subj", f"/CN={name}", "-addext", "subjectAltName=IP:127.0.0.1",
         "-keyout", str(key), "-out", str(cert)],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


def test_tls_with_client_certificates(tmp_path: Path) -> None:
    ctc_cert, ctc_key = self_signed(tmp_path, "ctc")
    ixl_cert, ixl_key = self_signed(tmp_path, "ixl20")
    stranger_cert, stranger_key = self_signed(tmp_path, "stranger")

    server_ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH, cafile=str(ixl_cert))
    server_ctx.load_cert_chain(ctc_cert, ctc_key)
    server_ctx.verify_mode = ssl.CERT_REQUIRED

    def client_ctx(cert: Path, key: Path) -> ssl.SSLContext:
        ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=str(ctc_cert))
        ctx.load_cert_chain(cert, key)
        return ctx

    async def main() -> None:
        app = StateTable({c: c % 2 for c in range(1, 101)})
        tables = IndicationTables([20, 22])
        async with CtcServer([20, 22], tables, ssl=server_ctx) as ctc:
            good = IxlClient(20, "127.0.0.1", ctc.port, app, ssl=client_ctx(ixl_cert, ixl_key),
                             server_hostname="127.0.0.1", backoff_initial=0.02, backoff_max=0.1)  # fmt: skip
            bad = IxlClient(22, "127.0.0.1", ctc.port, app,
                            ssl=client_ctx(stranger_cert, stranger_key),
                            server_hostname="127.0.0.1", backoff_initial=0.02, backoff_max=0.1)  # fmt: skip
            async with good, bad:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                assert tables.stations[20].state == app.state
                await bad.wait_until(lambda: bad.attempts >= 3)
                assert not tables.stations[22].connected and bad.connections == 0

    run(main())
