"""The lab file's `hosts:` section: the computers a lab spreads over (SPEC §10).

    hosts:
      central: {address: 10.0.0.1, control: 7700}
      st20:    {address: 10.0.0.20, control: 7700, token_file: /etc/ktcs/lab.token}
    devices:
      ixl20: {kind: ixl, station: 20, host: st20}

A host has an `address` (where its devices bind and are reached: never assumed to be loopback)
and `control`, the fixed port its `lab up --host NAME` serves the lab's control on, so the other
hosts find it; the services a host offers the others (the CTC's Type II, the rails, a Type I line
over RFC 2217) are on the ports after it (`lab.multihost.Placement`). `token_file`: where that
host keeps the lab's token (a path on that host; relative: to the lab file's folder), when
`lab up --token-file` does not say. With `hosts:`, every device names its host (`host: NAME`, or
the address of one of the hosts)."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.schema import Shape, convert
from ktcs_bench.transport.endpoints import PORT_MAX, check_port

_Fail = Callable[[str, str], ConfigError]
_ADDRESS = re.compile(r"[A-Za-z0-9._-]+")  # a host name or an IPv4 address


@dataclass(frozen=True)
class HostSpec:
    """One host of a spread lab: its address, the port its lab runner serves control on, and
    where it keeps the lab's token (None: `lab up --token-file` must say)."""

    name: str
    address: str
    control: int
    token_file: Path | None = None


class _HostShape(Shape):
    address: str
    control: Any
    token_file: str | None = None


def parse_hosts(section: object, file: Path, fail: _Fail) -> dict[str, HostSpec]:
    """The `hosts:` section (absent: {}, a lab on one machine)."""
    if section is None:
        return {}
    if not isinstance(section, dict) or not section:
        raise fail("hosts", "must be a mapping NAME -> {address, control}")
    hosts: dict[str, HostSpec] = {}
    for hname, spec in section.items():
        name, place = str(hname), f"hosts.{hname}"
        if not isinstance(spec, dict):
            raise fail(place, "must be a mapping {address: ADDRESS, control: PORT}")
        shape = convert(spec, _HostShape, file, place)
        address = shape.address.strip()
        if _ADDRESS.fullmatch(address.rpartition(":")[0]) and address.rpartition(":")[2].isdigit():
            raise fail(f"{place}.address", f"the address alone, not {excerpt(address)} (the "
                       "host's ports follow from its `control`)")  # fmt: skip
        if ":" in address and _ADDRESS.fullmatch(address.replace(":", "")):
            raise fail(f"{place}.address", "an IPv6 address is not taken here (the lab writes "
                       "HOST:PORT endpoints): give a host name that resolves to it")  # fmt: skip
        if not _ADDRESS.fullmatch(address):
            raise fail(f"{place}.address", f"a host name or IP address, not {excerpt(address)}")
        try:
            control = check_port(shape.control)
        except UsageError as exc:
            raise fail(f"{place}.control", f"a fixed port: {exc}") from None
        if control >= PORT_MAX:
            raise fail(f"{place}.control", f"port {control} leaves no port after it for the "
                       "services this host offers the others")  # fmt: skip
        token = None
        if shape.token_file is not None:
            if not shape.token_file.strip():
                raise fail(f"{place}.token_file", "a path on that host, not empty")
            token = file.parent / shape.token_file.strip()
        for other in hosts.values():
            if other.address == address:
                raise fail(f"{place}.address", f"{address} is host {other.name}'s address too")
        hosts[name] = HostSpec(name, address, control, token)
    return hosts


def device_address(
    given: object, hosts: Mapping[str, HostSpec], place: str, fail: _Fail
) -> str | None:
    """The address a device's `host:` names (`given`: its raw value, None when absent): a host
    of `hosts:` or one's address; with no `hosts:`, any address (None: absent there, the
    default). A ConfigError at `place` otherwise."""
    if not hosts:
        return None
    names = ", ".join(hosts)
    if given is None:
        raise fail(place, f"the lab spreads over hosts ({names}): name the one this device runs on")
    text = str(given)
    if text in hosts:
        return hosts[text].address
    if any(h.address == text for h in hosts.values()):
        return text
    raise fail(place, f"{excerpt(given)} is not a host of the lab ({names}) nor one's address")
