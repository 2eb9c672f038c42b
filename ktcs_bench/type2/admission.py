"""Who may hold a Type II connection at the CTC (SPEC §4, §10): a pure policy, no I/O.

Rules: only configured stations; one connection per station; optionally only from configured
source addresses (per link, or per station); the right protocol version; and a peer that keeps
sending bad frames is dropped. The server asks, acts on the `Decision` and logs refusals with the
peer's address.
"""

from __future__ import annotations

import ipaddress
from collections import deque
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass

from ktcs_bench.errors import UsageError

Network = ipaddress.IPv4Network | ipaddress.IPv6Network

# Bad records tolerated per connection inside the window. One damaged frame can decode as an error
# frame plus a garbage remnant (2 records), and is refused up to retry_count + 1 = 4 times: 8 is
# still ordinary ARQ work; a dozen in ten seconds is a broken or hostile peer.
DEFAULT_BAD_FRAME_LIMIT = 12
DEFAULT_BAD_FRAME_WINDOW = 10.0


@dataclass(frozen=True, slots=True)
class Decision:
    admitted: bool
    reason: str = ""

    def __bool__(self) -> bool:
        return self.admitted


ADMIT = Decision(True)


def _networks(specs: Iterable[str], what: str) -> tuple[Network, ...]:
    out = []
    for spec in specs:
        try:
            out.append(ipaddress.ip_network(spec, strict=False))
        except ValueError:
            raise UsageError(f"{what}: {spec!r} is not an IP address or network") from None
    return tuple(out)


def _host_of(address: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        addr = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:
        return None
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        return addr.ipv4_mapped
    return addr


class AdmissionPolicy:
    """The CTC's admission rules for Type II.

    `stations`: the station numbers configured in the lab. `allowed_sources`: if given, the only
    addresses/networks ("10.0.0.0/24", "127.0.0.1") any IXL may connect from.
    `station_sources`: per station, the addresses/networks that station may connect from.
    """

    def __init__(
        self,
        stations: Iterable[int],
        *,
        allowed_sources: Iterable[str] | None = None,
        station_sources: Mapping[int, Iterable[str]] | None = None,
        version: int = 1,
        bad_frame_limit: int = DEFAULT_BAD_FRAME_LIMIT,
        bad_frame_window: float = DEFAULT_BAD_FRAME_WINDOW,
    ) -> None:
        self.stations = frozenset(int(s) for s in stations)
        self.allowed_sources = (
            None if allowed_sources is None else _networks(allowed_sources, "allowed source")
        )
        self.station_sources = {
            int(st): _networks(nets, f"sources of station {st}")
            for st, nets in (station_sources or {}).items()
        }
        self.version = version
        if bad_frame_limit < 1 or bad_frame_window <= 0:
            raise UsageError("bad_frame_limit must be >= 1 and bad_frame_window positive")
        self.bad_frame_limit = bad_frame_limit
        self.bad_frame_window = bad_frame_window

    def check_address(self, host: str) -> Decision:
        """At TCP accept, before any byte is read."""
        if self.allowed_sources is None:
            return ADMIT
        if _in(host, self.allowed_sources):
            return ADMIT
        return Decision(False, f"source address {host} is not allowed")

    def check_ident(
        self, station: int, version: int, host: str, connected: Collection[int]
    ) -> Decision:
        """At IDENT: `connected` = stations that already hold an identified connection."""
        if station not in self.stations:
            return Decision(False, f"station {station} is not configured")
        if version != self.version:
            return Decision(False, f"protocol version {version} (this CTC speaks {self.version})")
        nets = self.station_sources.get(station)
        if nets is not None and not _in(host, nets):
            return Decision(False, f"station {station} may not connect from {host}")
        if station in connected:
            return Decision(False, f"station {station} is already connected")
        return ADMIT

    def bad_frame_meter(self) -> BadFrameMeter:
        """A fresh meter for one connection."""
        return BadFrameMeter(self.bad_frame_limit, self.bad_frame_window)


def _in(host: str, nets: Iterable[Network]) -> bool:
    addr = _host_of(host)
    return addr is not None and any(addr in net for net in nets)


class BadFrameMeter:
    """Counts bad frames from one peer in a sliding window; `record(now)` says when to drop it."""

    def __init__(self, limit: int, window: float) -> None:
        self.limit = limit
        self.window = window
        self._times: deque[float] = deque()

    def record(self, now: float) -> Decision:
        times = self._times
        times.append(now)
        while times and now - times[0] > self.window:
            times.popleft()
        if len(times) >= self.limit:
            return Decision(False, f"{len(times)} bad frames within {self.window:g} s")
        return ADMIT
