"""Conformance against a target that never answers is bounded and says so: the run stops after
its first case with exit 3 and "no device answered" -- whatever the case's own time limit, the
report lists that one case, never the rest of the suite. Real sockets and a real pty."""

from __future__ import annotations

import os
import socket
import threading
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest

from .conftest import cli, free_port


def _stopped_after_one_case(run_args: list[str], junit: Path) -> tuple[str, str]:
    """(the one case's name, its error message)"""
    run = cli("conformance", *run_args, "--junit", str(junit), timeout=60)
    assert run.returncode == 3, run.stdout + run.stderr
    assert "no device answered" in run.stderr and "no device answered" in run.stdout
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None
    (case,) = suite.iter("testcase")
    error = case.find("error")
    assert error is not None and "no device answered" in error.get("message", "")
    return case.get("name", ""), error.get("message", "")


def test_a_silent_pty(tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        name, _ = _stopped_after_one_case(
            ["--role", "atc", "--target", os.ttyname(slave), "--unpaced"], tmp_path / "r.xml"
        )
    finally:
        os.close(master)
        os.close(slave)
    assert name == "framing"


@pytest.fixture
def accept_and_close() -> Iterator[int]:
    """A TCP port that accepts every connection and closes it at once (a dead service behind a
    live listener)."""
    server = socket.create_server(("127.0.0.1", 0))
    accepted: list[int] = []

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            accepted.append(1)
            conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield int(server.getsockname()[1])
    server.shutdown(socket.SHUT_RDWR)
    server.close()
    thread.join(5)
    assert accepted, "the suite never connected: the test proved nothing"


def test_a_type2_port_that_accepts_and_closes(accept_and_close: int, tmp_path: Path) -> None:
    name, _ = _stopped_after_one_case(
        ["--role", "ctc", "--target", f"tcp://127.0.0.1:{accept_and_close}", "--station", "18"],
        tmp_path / "r.xml",
    )
    assert name == "t2-ident"


def test_listen_with_nobody_coming(tmp_path: Path) -> None:
    port = free_port()
    name, message = _stopped_after_one_case(
        ["--role", "ixl", "--target", f"listen://127.0.0.1:{port}"], tmp_path / "r.xml"
    )
    assert name == "t2-ident" and "no IXL connected" in message
