"""Endpoints as a user writes them (`--link PEER=ENDPOINT`, lab files), parsed once.

Type I: a device path or any pyserial URL (`/dev/ttyUSB0`, `loop://`, `socket://h:p`,
`rfc2217://h:p`), or `pty` (make a pty pair here and print the path to give the peer).
TCP: `tcp://HOST:PORT` (connect) or `listen://HOST:PORT` (serve).
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.errors import UsageError


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
            host, sep, port = text[len(scheme) + 3 :].rpartition(":")
            if not sep or not port.isdigit() or not host:
                raise UsageError(f"endpoint {text!r}: expected {scheme}://HOST:PORT")
            return Endpoint(scheme, text, host.strip("[]"), int(port))
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
