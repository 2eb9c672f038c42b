"""A blocking client for a tap's control port: send commands, or subscribe to its traffic.

The port speaks JSON lines (`control.py`); `command()` takes the words a person types and sends
their JSON, `request()` sends JSON as it is. The client presents the tap's token first
(`{"token": TOKEN}`, answered `{"ok": true}`), as every client of a control port does.
"""

from __future__ import annotations

import contextlib
import json
import socket
from collections.abc import Iterator, Mapping
from typing import cast

from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.runtime import client_token
from ktcs_bench.tap.control import Command, parse_command
from ktcs_bench.tap.core import TapEvent
from ktcs_bench.tap.registry import resolve_tap
from ktcs_bench.tap.runner import TapStatus


class TapLine(TapEvent, total=False):
    """A line a tap's control port sends: an answer (`runner.TapAnswer`), the subscribe header
    or an event of its stream (`TapEvent`). Every key may be missing: the client checks those it
    needs before it trusts what answers to be a tap."""

    ok: bool
    refused: bool  # before the token: nothing was done
    status: TapStatus
    help: str


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
        self._send({"token": token})
        answer = self._read()
        host, port = self.address
        if answer.get("refused"):
            raise PeerError(f"the tap at {host}:{port} {answer.get('error')}")
        if answer != {"ok": True}:  # never repeat what it said: it may be our token echoed
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

    def _read(self) -> TapLine:
        try:
            line = self._file.readline()
        except OSError as exc:
            raise PeerError(f"tap control port: {exc}") from None
        if not line:
            raise PeerError("the tap closed its control port")
        return self._json(line.decode("utf-8", errors="replace"))

    def _json(self, text: str) -> TapLine:
        try:
            obj = json.loads(text)
        except ValueError:
            obj = None
        if not isinstance(obj, dict):
            raise PeerError(self._not_a_tap(text))
        return cast(TapLine, obj)  # each key is checked where it is used

    def _not_a_tap(self, reply: object) -> str:
        host, port = self.address
        return f"{host}:{port} is not a tap's control port (it answered {str(reply)[:60]!r})"

    def _send(self, obj: Mapping[str, object]) -> None:
        try:
            self._file.write(json.dumps(obj, separators=(",", ":")).encode() + b"\n")
            self._file.flush()
        except OSError as exc:
            raise PeerError(f"tap control port: {exc}") from None

    def request(self, obj: Mapping[str, object]) -> TapLine:
        """One JSON command, its answer. Raises UsageError when the tap refuses it, PeerError
        when what answers is not a tap."""
        self._send(obj)
        answer = self._read()
        if answer.get("ok") is True:
            return answer
        if answer.get("refused"):
            host, port = self.address
            raise PeerError(f"the tap at {host}:{port} {answer.get('error')}")
        if answer.get("ok") is False and isinstance(answer.get("error"), str):
            raise UsageError(f"tap: {answer['error']}")
        raise PeerError(self._not_a_tap(json.dumps(answer)))

    def command(self, line: str) -> str:
        """Send one command given as words (`ber 1e-3 ixl>atc`); what it did, as words (the
        status as JSON, the help as text)."""
        cmd = parse_command(line)
        if cmd.verb == "subscribe":
            raise UsageError("subscribe: use TapClient.subscribe()")
        answer = self.request(cmd.to_json())
        if cmd.verb == "status":
            return json.dumps(self._status(answer))
        if cmd.verb == "help":
            return str(answer.get("help", ""))
        return str(answer.get("command", cmd.words()))

    def _status(self, answer: TapLine) -> TapStatus:
        status = answer.get("status")
        if not (isinstance(status, dict) and isinstance(status.get("directions"), dict)):
            raise PeerError(self._not_a_tap(json.dumps(answer)))  # a device's port, say
        return status

    def status(self) -> TapStatus:
        return self._status(self.request({"cmd": "status"}))

    def subscribe(self, history: bool = False, timeout: float | None = None) -> Iterator[TapEvent]:
        """The header ({profile, names, ...}) first, then one dict per record or event."""
        header = self.request(Command("subscribe", history=history).to_json())
        if not isinstance(header.get("names"), list) or "profile" not in header:
            raise PeerError(self._not_a_tap(json.dumps(header)))
        header.pop("ok")
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
