"""Endpoints as a user writes them (`--link PEER=ENDPOINT`, lab files), parsed once.

Type I: a device path or any pyserial URL (`/dev/ttyUSB0`, `loop://`, `socket://h:p`,
`rfc2217://h:p`), or `pty` (make a pty pair here and print the path to give the peer).
TCP: `tcp://HOST:PORT` (connect) or `listen://HOST:PORT` (serve).

Every port a user gives goes through `check_port`: 1..65535, and 0 ("any free port") only where
something is served. A port out of range is a UsageError; it never reaches the socket layer,
which would raise OverflowError on bind and wrap it modulo 65536 on connect.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ktcs_bench.errors import UsageError

PORT_MAX = 65535
_INTEGER = re.compile(r"[+-]?[0-9]+")


def check_port(value: object, what: str = "", *, any_free: bool = False) -> int:
    """`value` (an int or its digits) as a TCP port number, or a UsageError naming `what`.
    `any_free`: 0 is allowed too (a server binds any free port)."""
    low = 0 if any_free else 1
    free = " (0: any free port)" if any_free else ""
    text = str(value).strip()
    number = isinstance(value, int) or (isinstance(value, str) and _INTEGER.fullmatch(text))
    if isinstance(value, bool) or not number:
        problem = f"the port must be a number {low}..{PORT_MAX}{free}, not {text!r}"
    elif not low <= int(text) <= PORT_MAX:
        problem = f"port {int(text)} is out of range {low}..{PORT_MAX}{free}"
    else:
        return int(text)
    raise UsageError(f"{what}: {problem}" if what else problem)


def parse_host_port(
    text: str, what: str = "", *, any_free: bool = False, default_host: str = "127.0.0.1"
) -> tuple[str, int]:
    """`HOST:PORT`, `[V6]:PORT` or `:PORT` -> (host, port), the port range-checked."""
    host, sep, port = text.strip().rpartition(":")
    if not sep:
        problem = f"expected HOST:PORT, not {text!r}"
        raise UsageError(f"{what}: {problem}" if what else problem)
    return host.strip("[]") or default_host, check_port(port, what, any_free=any_free)


@dataclass(frozen=True, slots=True)
class Endpoint:
    kind: str  # "serial" | "pty" | "tcp" | "listen"
    address: str  # device path / URL for serial; "" for pty
    host: str = ""
    port: int = 0

    def __str__(self) -> str:
        if self.kind in ("tcp", "listen"):
            return f"{self.kind}://{self.host}:{self.port}"
        return self.address or self.kind


def parse_endpoint(text: str) -> Endpoint:
    text = text.strip()
    if not text:
        raise UsageError("empty endpoint")
    if text == "pty":
        return Endpoint("pty", "")
    for scheme in ("tcp", "listen"):
        if text.startswith(f"{scheme}://"):
            rest = text[len(scheme) + 3 :]
            if ":" not in rest or rest.startswith(":"):
                raise UsageError(f"endpoint {text!r}: expected {scheme}://HOST:PORT")
            host, port = parse_host_port(rest, f"endpoint {text}", any_free=scheme == "listen")
            return Endpoint(scheme, text, host, port)
    return Endpoint("serial", text)


def parse_links(items: list[str]) -> dict[str, Endpoint]:
    """`["atc18=pty", "ctc=tcp://127.0.0.1:5000"]` -> {peer: Endpoint}."""
    out: dict[str, Endpoint] = {}
    for item in items:
        peer, sep, value = item.partition("=")
        if not sep or not peer:
            raise UsageError(f"--link {item!r}: expected PEER=ENDPOINT")
        out[peer.strip()] = parse_endpoint(value)
    return out
