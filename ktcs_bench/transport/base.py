"""The one `Transport` shape every wire adapter has (python-can's BusABC, cut down to bytes).

Owns: the `Transport` protocol, `TransportBase` (context manager, name) and `TransportClosed`.
A transport moves bytes and nothing else: `send()` queues bytes and returns at once (a paced
transport releases them at the line rate behind the caller's back); `recv(timeout)` returns what
has arrived (b"" when nothing came within `timeout`); `fileno()` gives an event loop a readable fd,
or None when the transport can only be polled. Protocol rules never live here.
"""

from __future__ import annotations

from collections.abc import Callable
from types import TracebackType
from typing import Protocol, Self, runtime_checkable

from ktcs_bench.errors import KtcsError


class TransportClosed(KtcsError):
    """The transport was closed, or the far end hung up."""


@runtime_checkable
class Transport(Protocol):
    name: str

    def send(self, data: bytes) -> None: ...

    def recv(self, timeout: float | None = None) -> bytes: ...

    def fileno(self) -> int | None: ...

    def drain(self, timeout: float | None = None) -> bool: ...

    def close(self) -> None: ...


@runtime_checkable
class PushTransport(Transport, Protocol):
    """A transport that hands what arrives to a callback instead of being read (a virtual wire
    in a lab run in one process): no fd, no reader thread."""

    def attach(
        self, on_data: Callable[[bytes], None], on_closed: Callable[[BaseException], None]
    ) -> None: ...


class TransportBase:
    """Context manager and naming shared by the concrete transports."""

    name: str = "transport"

    def close(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def shutdown(self) -> None:
        """python-can's spelling of `close()`."""
        self.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"
