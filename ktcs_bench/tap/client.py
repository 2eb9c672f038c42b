"""A blocking client for a tap's control port: send commands, or subscribe to its traffic."""

from __future__ import annotations

import contextlib
import json
import socket
from collections.abc import Iterator
from typing import Any

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.runtime import client_token
from ktcs_bench.tap.registry import resolve_tap


class TapClient:
    """`TapClient("st18-ixl-atc").command("cut")`; `for ev in TapClient(addr).subscribe(): ...`.
    It presents the tap's token first: `token`, else the one `runtime.client_token` finds."""

    def __init__(
        self, tap: str | tuple[str, int], timeout: float = 5.0, token: str | None = None
    ) -> None:
        self.address = resolve_tap(tap) if isinstance(tap, str) else tap
        token = token if token is not None else client_token(self.address)
        try:
            self._sock = socket.create_connection(self.address, timeout=timeout)
        except OSError as exc:
            host, port = self.address
            raise PeerError(f"cannot reach the tap's control port {host}:{port}: {exc}") from None
        self._file = self._sock.makefile("rwb")
        if token:
            try:
                self._present(token)
            except BaseException:
                self.close()
                raise

    def _present(self, token: str) -> None:
        try:
            self._file.write(f"token {token}\n".encode())
            self._file.flush()
        except OSError as exc:
            raise PeerError(f"tap control port: {exc}") from None
        reply = self._readline()
        host, port = self.address
        if reply.startswith("error refused"):
            raise PeerError(f"the tap at {host}:{port} {reply[6:]}")
        if reply != "ok":  # never repeat what it said: it may be our token echoed
            raise PeerError(f"{host}:{port} is not a tap's control port (no tap answers so)")

    def close(self) -> None:
        """Also ends a `subscribe()` blocked in another thread (the socket is shut down first)."""
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._file.close()
        self._sock.close()

    def __enter__(self) -> TapClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _readline(self) -> str:
        try:
            line = self._file.readline()
        except OSError as exc:
            raise PeerError(f"tap control port: {exc}") from None
        if not line:
            raise PeerError("the tap closed its control port")
        return line.decode("utf-8", errors="replace").rstrip("\n")

    def command(self, line: str) -> str:
        """Send one command; the reply without its `ok ` prefix. Raises UsageError on `error`,
        PeerError when what answers is not a tap."""
        try:
            self._file.write(line.strip().encode() + b"\n")
            self._file.flush()
        except OSError as exc:
            raise PeerError(f"tap control port: {exc}") from None
        reply = self._readline()
        if reply.startswith("error refused"):
            host, port = self.address
            raise PeerError(f"the tap at {host}:{port} {reply[6:]}")
        if reply.startswith("error"):
            raise UsageError(f"tap: {reply[6:]}")
        if reply != "ok" and not reply.startswith("ok "):
            raise PeerError(self._not_a_tap(reply))
        return reply[3:]

    def _not_a_tap(self, reply: str) -> str:
        host, port = self.address
        return f"{host}:{port} is not a tap's control port (it answered {reply[:60]!r})"

    def _json(self, text: str) -> dict[str, Any]:
        try:
            obj = json.loads(text)
        except ValueError:
            obj = None
        if not isinstance(obj, dict):
            raise PeerError(self._not_a_tap(text))
        return obj

    def status(self) -> dict[str, Any]:
        return self._json(self.command("status"))

    def subscribe(
        self, history: bool = False, timeout: float | None = None
    ) -> Iterator[dict[str, Any]]:
        """The header ({profile, names, ...}) first, then one dict per record or event."""
        header = self._json(self.command("subscribe history" if history else "subscribe"))
        self._sock.settimeout(timeout)
        yield header
        while True:
            try:
                line = self._file.readline()
            except TimeoutError:
                return
            except OSError as exc:
                raise PeerError(f"tap control port: {exc}") from None
            if not line:
                return
            yield self._json(line.decode("utf-8", errors="replace"))
