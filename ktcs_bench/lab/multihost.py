"""One lab file, several hosts (SPEC §10): `lab up LAB --host NAME` runs the part of the lab the
file places on host NAME (`hosts:`, `lab.hosts`) and links it to the other parts over the network.

Which host runs what:
- each device runs on its own host (`host:`);
- **a link's tap runs on the host of its end a** (the IXL; across an interval, the west one), so
  the capture and the faults of a station's links are on that station's computer;
- Type II: the tap connects on to the CTC's Type II port on the CTC's host;
- Type I with both ends on one host: a pty pair per end, as on one machine; with end b on
  another host, b's device makes its own pty (`--link ROLE=pty`), b's host serves that pty over
  RFC 2217 (`transport.rfc2217_server`), and the tap on a's host opens `rfc2217://B:PORT` as the
  lab opens an external device's line;
- the rails: the track-circuit emulator's host serves them; ATCs, trackside and trains join them
  at that address.

Every port another host needs is fixed by the lab file, so the hosts' commands may start in any
order and find one another again after a network cut, with nothing exchanged first: a host
serves its lab control on `hosts.NAME.control` (P), and the services it offers the others on
P+1, P+2, ... in this order: the CTC's Type II (unless `type2.port` fixes it), the rails (unless
the track-circuit device has a `port`), then one RFC 2217 port per Type I link whose end b is
there and whose end a is not, in the lab file's order (`Placement.ports`; `lab map` shows them).

From a host, the devices of the other hosts look like external devices (`Placement.view`): a CTC
elsewhere is an address to connect to, a Type I peer elsewhere a pyserial URL the tap opens, so
the runner of one host (`HostRunner`) is the lab runner of one machine, with that view. Its lab
control port answers for the whole lab: `status` and `map` gather every host's part from its
runner over TCP (a host that does not answer is shown so, its devices not alive); `down` stops
this host's part, `down` with `all` every host's; `restart` and `kill` of a device elsewhere are
passed to its host. Every host's runner requires the same token: the lab's, which each host
reads from its own copy (`lab up --token-file`, or `hosts.NAME.token_file`).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, TypedDict

from ktcs_bench import kinds
from ktcs_bench.errors import KtcsError, UsageError
from ktcs_bench.lab.hosts import HostSpec
from ktcs_bench.lab.runner import LabRunner, lab_command
from ktcs_bench.lab.topology import External, Lab, LinkSpec
from ktcs_bench.lab.view import LinkEntry
from ktcs_bench.messages import JsonObject
from ktcs_bench.runtime import TOKEN_ENV, server_token
from ktcs_bench.transport import jsonlines
from ktcs_bench.transport.rfc2217_server import Rfc2217Server

PART_TIMEOUT = 3.0  # s another host's runner has to answer for its part (a cut host does not)
TYPE2, RAILS = "type2", "rails"  # services of `Placement.ports`, besides "control" and links'


def rfc2217_service(link: str) -> str:
    return f"rfc2217 {link}"


@dataclass(frozen=True)
class Placement:
    """Where a spread lab's devices, taps and services are, from its lab file alone."""

    lab: Lab

    def __post_init__(self) -> None:
        if not self.lab.hosts:
            raise UsageError(f"lab {self.lab.name} names no hosts (`hosts:` in {self.lab.file}): "
                             "it runs on one machine, with `lab up` and no --host")  # fmt: skip

    def host(self, name: str) -> HostSpec:
        if name not in self.lab.hosts:
            raise UsageError(f"no host {name!r} in lab {self.lab.name} "
                             f"({', '.join(self.lab.hosts)})")  # fmt: skip
        return self.lab.hosts[name]

    def host_of(self, device: str) -> str:
        """The host device `device` is placed on (its `host:` is one's address: `lab.hosts`)."""
        address = self.lab.devices[device].host
        return next(h.name for h in self.lab.hosts.values() if h.address == address)

    def tap_host(self, link: LinkSpec) -> str:
        """The host that runs `link`'s tap: its end a's."""
        return self.host_of(link.a)

    def crosses(self, link: LinkSpec) -> bool:
        """A Type I link between devices of the lab on two hosts: served over RFC 2217 from end
        b's host. (A real device's line the tap opens itself, wherever its `host:` says.)"""
        a, b = self.lab.devices[link.a], self.lab.devices[link.b]
        return (link.type == kinds.TYPE1 and a.external is None and b.external is None
                and a.host != b.host)  # fmt: skip

    def devices_on(self, host: str) -> list[str]:
        return [n for n in self.lab.devices if self.host_of(n) == host]

    @cached_property
    def ports(self) -> dict[str, dict[str, int]]:
        """host -> service -> port: "control", TYPE2, RAILS, `rfc2217_service(LINK)`."""
        out: dict[str, dict[str, int]] = {}
        for h in self.lab.hosts.values():
            ports = out[h.name] = {"control": h.control}
            here = self.devices_on(h.name)
            services = []
            for name in here:
                d = self.lab.devices[name]
                if d.kind == kinds.CTC and d.external is None:
                    services.append((TYPE2, self.lab.type2_port))
                if d.kind == kinds.TRACKCIRCUIT and d.external is None:
                    services.append((RAILS, int(d.options.get("port") or 0)))
            services += [(rfc2217_service(lk.name), 0) for lk in self.lab.links
                         if self.crosses(lk) and lk.b in here]  # fmt: skip
            after = h.control
            for service, fixed in services:
                if not fixed:
                    after += 1
                ports[service] = fixed or after
            if after > 65535:
                raise UsageError(f"host {h.name}: its services need ports {h.control + 1}.."
                                 f"{after}, past 65535: give it a lower control port")  # fmt: skip
        return out

    def service(self, service: str) -> tuple[str, int]:
        """(address, port) of `service` on whichever host offers it."""
        for host, ports in self.ports.items():
            if service in ports:
                return self.lab.hosts[host].address, ports[service]
        raise UsageError(f"lab {self.lab.name}: no host offers {service}")

    def type2_address(self) -> tuple[str, int]:
        for ctc in self.lab.of_kind(kinds.CTC):
            if ctc.external is not None and ctc.external.address is not None:
                return ctc.external.address
        return self.service(TYPE2)

    def rfc2217_url(self, link: LinkSpec) -> str:
        host, port = self.service(rfc2217_service(link.name))
        return f"rfc2217://{host}:{port}"

    def view(self, host: str) -> Lab:
        """The lab as host `host` runs it: its devices, the links whose tap it runs, and each
        such link's end on another host as an external device (a CTC's address, a Type I line's
        RFC 2217 URL). Its CTC's Type II port and its rails' port are the fixed ones."""
        self.host(host)
        here = set(self.devices_on(host))
        links = tuple(lk for lk in self.lab.links if lk.a in here)
        devices = {n: d for n, d in self.lab.devices.items() if n in here}
        for lk in links:
            if lk.b in devices:
                continue
            b = self.lab.devices[lk.b]
            if b.external is None and lk.type == kinds.TYPE2:
                b = replace(b, external=External(address=self.type2_address()))
            elif b.external is None:
                b = replace(b, external=External(serial=self.rfc2217_url(lk)))
            devices[lk.b] = b
        ports = self.ports[host]
        for name, d in devices.items():
            if d.kind == kinds.TRACKCIRCUIT and d.external is None:
                devices[name] = replace(d, options={**d.options, "port": ports[RAILS]})
        return replace(self.lab, devices=devices, links=links,
                       type2_port=ports.get(TYPE2, self.lab.type2_port))  # fmt: skip

    def token_file(self, host: str, given: str | None) -> Path:
        """Where host `host` reads the lab's token: `given` (`--token-file`), else its
        `token_file:`, else $KTCS_BENCH_TOKEN_FILE. Every host needs the same token and no
        folder is shared, so one must say (the first host makes the file if it is missing)."""
        spec = self.host(host)
        if given:
            return Path(given)
        if spec.token_file is not None:
            return spec.token_file
        if os.environ.get(TOKEN_ENV):
            return Path(os.environ[TOKEN_ENV])
        raise UsageError(
            f"lab up --host {host}: every host of lab {self.lab.name} must present the same token "
            f"and no folder is shared: give --token-file FILE (made there if missing; copy it to "
            f"each host, mode 0600), or hosts.{host}.token_file in {self.lab.file}, or "
            f"${TOKEN_ENV}"
        )


class HostState(TypedDict):
    """A host in a spread lab's status: its address and ports, and whether its runner answered
    (`error`: why not)."""

    address: str
    ports: dict[str, int]
    reached: bool
    up: bool  # its every device started (reached but not up: still starting)
    error: str | None


class LinkState(TypedDict):
    """A link in a spread lab's status: the host that runs its tap, its ends, up or not."""

    host: str
    type: str
    a: str
    b: str
    up: bool


@dataclass
class HostRunner(LabRunner):
    """The lab runner of one host of a spread lab: `lab` is that host's view
    (`Placement.view`), `placement` the whole lab's."""

    placement: Placement | None = None
    here: str = ""
    servers: dict[str, Rfc2217Server] = field(default_factory=dict)  # link -> RFC 2217 server
    started: bool = False  # every device of this host started (its control answers before)

    @property
    def place(self) -> Placement:
        assert self.placement is not None
        return self.placement

    @property
    def whole(self) -> Lab:
        return self.place.lab

    def _served_links(self) -> list[LinkSpec]:
        """The Type I links whose end b is here and end a elsewhere: served over RFC 2217."""
        return [lk for lk in self.whole.links if self.place.crosses(lk)
                and self.place.host_of(lk.b) == self.here]  # fmt: skip

    async def up(self) -> None:
        """The links to other hosts first (the rails' address, a pty served over RFC 2217 for
        each Type I end here whose tap is elsewhere), then the lab runner's start."""
        self._check_address()
        self.token, self.token_file = server_token(self.token_file)
        await self._serve_control()  # first: a port taken fails before any device starts
        rails = next((d for d in self.whole.of_kind(kinds.TRACKCIRCUIT)), None)
        if rails is not None and rails.name not in self.lab.devices:
            host, port = self.place.service(RAILS)
            for d in self.lab.devices.values():
                if kinds.KINDS[d.kind].rails and d.external is None:
                    self.endpoints.setdefault(d.name, {})[kinds.RAILS] = f"tcp://{host}:{port}"
        for lk in self._served_links():
            role = self.whole.peer_role(lk, lk.b)
            self.endpoints.setdefault(lk.b, {})[role] = "pty"
            address = self.place.service(rfc2217_service(lk.name))
            server = Rfc2217Server(address, self._pty_of(lk.b, role), name=lk.name)
            with self._serving(f"the RFC 2217 line of link {lk.name}", address):
                server.start()
            self.servers[lk.name] = server
        await super().up()
        self.started = True

    def _check_address(self) -> None:
        """This machine has host `here`'s address (a UsageError if not: the wrong --host)."""
        address = self.place.host(self.here).address
        with socket.socket() as probe:
            try:
                probe.bind((address, 0))
            except OSError as exc:
                raise UsageError(
                    f"host {self.here} of lab {self.whole.name} is at {address}, which is not an "
                    f"address of this machine ({exc.strerror}): run `lab up --host {self.here}` "
                    "on that host"
                ) from None

    @contextlib.contextmanager
    def _serving(self, what: str, address: tuple[str, int]) -> Iterator[None]:
        """A port of this host's that the lab file fixes: a UsageError if it cannot be served."""
        try:
            yield
        except OSError as exc:
            raise UsageError(
                f"host {self.here} cannot serve {what} on {address[0]}:{address[1]}: "
                f"{exc.strerror or exc} (is another lab up here, or another program on the "
                f"port? {self.whole.file} fixes the ports from hosts.{self.here}.control)"
            ) from None

    def _pty_of(self, device: str, role: str) -> Callable[[], str | None]:
        """Where device `device`'s pty for `role` is now (None: not started yet)."""

        def path() -> str | None:
            child = self.children.get(device)
            return None if child is None else (child.ready.get("ptys") or {}).get(role)

        return path

    async def _serve_control(self) -> None:
        if getattr(self, "_control", None) is not None:
            return  # served already, before the devices started
        spec = self.place.host(self.here)
        with self._serving("the lab control", (spec.address, spec.control)):
            self._control = await jsonlines.serve(spec.address, spec.control, self._handle,
                                                  token=self.token)  # fmt: skip
        self.control_address = f"{spec.address}:{spec.control}"

    async def down(self) -> None:
        for server in self.servers.values():
            await asyncio.to_thread(server.stop)
        await super().down()

    # -- the whole lab, from every host's part ------------------------------------------------
    async def _handle(self, obj: JsonObject, peer: jsonlines.Peer) -> dict[str, Any]:
        cmd = obj.get("cmd")
        if obj.get("part") and cmd == "status":
            return {"ok": True, "status": await self.part_status()}
        if obj.get("part") and cmd == "map":
            return {"ok": True, "links": self.part_map()}
        if cmd == "map":
            return {"ok": True, "links": await self.whole_map()}
        if cmd == "down" and obj.get("all"):
            others = await self._ask_others({"cmd": "down"})
            self.stop_requested.set()
            return {"ok": True, "hosts": {h: a.get("error") or "stopping"
                                          for h, a in others.items()}}  # fmt: skip
        if cmd in ("restart", "kill") and str(obj.get("device")) in self.whole.devices:
            owner = self.place.host_of(str(obj["device"]))
            if owner != self.here:
                return await self._ask(owner, dict(obj), timeout=60.0)
        return await lab_command(self, obj)

    async def _ask(self, host: str, obj: JsonObject, timeout: float = PART_TIMEOUT) -> JsonObject:
        """A command to host `host`'s runner; {"ok": False, "error": ...} when it does not
        answer (its network cut, its part not up)."""
        spec = self.place.host(host)
        try:
            answer = await jsonlines.request(spec.address, spec.control, obj, timeout=timeout,
                                             token=self.token)  # fmt: skip
        except (OSError, TimeoutError, ValueError, KtcsError) as exc:
            why = str(exc) or type(exc).__name__
            return {"ok": False, "error": f"host {host} ({spec.address}:{spec.control}): {why}"}
        return dict(answer)

    async def _ask_others(self, obj: JsonObject) -> dict[str, JsonObject]:
        others = [h for h in self.whole.hosts if h != self.here]
        answers = await asyncio.gather(*(self._ask(h, obj) for h in others))
        return dict(zip(others, answers, strict=True))

    async def part_status(self) -> JsonObject:
        """This host's part: its devices, and the links whose tap runs here, each up or not."""
        base = await LabRunner.status(self)
        # ours here, and the real devices this host's taps reach (alive: their links here up)
        real = {n for n, d in self.whole.devices.items() if d.external is not None}
        mine = set(self.place.devices_on(self.here)) - real
        mine |= {n for lk in self.lab.links for n in (lk.a, lk.b) if n in real}
        statuses = {n: e.get("status") for n, e in base["devices"].items()}
        links: dict[str, LinkState] = {
            lk.name: {"host": self.here, "type": lk.type, "a": lk.a, "b": lk.b,
                      "up": self._link_up(lk, statuses, base["taps"])}
            for lk in self.lab.links
        }  # fmt: skip
        return {
            "lab": self.whole.name, "host": self.here, "up": self.started,
            "stations": base["stations"],
            "devices": {n: {**e, "host": self.place.host_of(n)}
                        for n, e in base["devices"].items() if n in mine},
            "taps": base["taps"], "links": links,
            "servers": {n: s.status() for n, s in self.servers.items()},
        }  # fmt: skip

    async def status(self) -> dict[str, Any]:
        """The whole lab: every host's part (`part_status`), gathered over TCP."""
        own, others = await asyncio.gather(
            self.part_status(), self._ask_others({"cmd": "status", "part": True})
        )
        parts: dict[str, JsonObject] = {self.here: {"ok": True, "status": own}, **others}
        hosts: dict[str, HostState] = {}
        stations: object = {}
        devices: JsonObject = {}
        taps: JsonObject = {}
        links: JsonObject = {}
        for host, answer in parts.items():
            part = answer.get("status")
            reached = bool(answer.get("ok")) and isinstance(part, dict)
            hosts[host] = {"address": self.whole.hosts[host].address, "ports": self.place.ports[host],
                           "reached": reached, "up": reached and bool(isinstance(part, dict) and part.get("up")),
                           "error": None if reached else str(answer.get("error"))}  # fmt: skip
            if not reached or not isinstance(part, dict):
                continue
            stations = stations or part.get("stations") or {}
            for key, into in (("taps", taps), ("links", links)):
                got = part.get(key)
                if isinstance(got, dict):
                    into.update(got)
            got = part.get("devices")
            for name, entry in (got if isinstance(got, dict) else {}).items():
                seen = devices.get(name)
                if isinstance(seen, dict) and isinstance(entry, dict):  # a real device reached
                    entry = {**seen, **entry,  # from several hosts: alive if all its links are
                             "alive": bool(seen.get("alive") and entry.get("alive")),
                             "links": {**(seen.get("links") or {}), **(entry.get("links") or {})}}  # fmt: skip
                devices[name] = entry
        for name in self.whole.devices:  # the devices of a host that did not answer
            devices.setdefault(name, {"alive": False, "crashed": None, "status": None,
                                      "host": self.place.host_of(name), "unreachable": True})  # fmt: skip
        for lk in self.whole.links:
            down: LinkState = {"host": self.place.tap_host(lk), "type": lk.type, "a": lk.a,
                               "b": lk.b, "up": False}  # fmt: skip
            links.setdefault(lk.name, down)
        return {
            "lab": self.whole.name, "host": self.here, "stations": stations,
            "devices": {n: devices[n] for n in self.whole.devices}, "taps": taps,
            "links": {lk.name: links[lk.name] for lk in self.whole.links}, "hosts": hosts,
        }  # fmt: skip

    def part_map(self) -> list[LinkEntry]:
        """This host's link map, each row with its host; its RFC 2217 servers as rows too."""
        rows: list[LinkEntry] = []
        for entry in self.link_map():
            row: LinkEntry = {**entry, "host": self.here}
            real = [n for n in entry.get("external", []) if self.whole.devices[n].external]
            if real:  # a device on another host is not external: it is the lab's, over there
                row["external"] = real
            else:
                row.pop("external", None)
            rows.append(row)
        for name, server in self.servers.items():
            lk = next(lk for lk in self.whole.links if lk.name == name)
            rows.append({"link": f"{name} rfc2217", "type": "rfc2217", "a": lk.b,
                         "a_end": f"rfc2217://{server.status()['listen']}", "host": self.here})  # fmt: skip
        return rows

    async def whole_map(self) -> list[LinkEntry]:
        others = await self._ask_others({"cmd": "map", "part": True})
        rows = self.part_map()
        for host, answer in others.items():
            links = answer.get("links")
            if answer.get("ok") and isinstance(links, list):
                rows += links
                continue
            rows += [{"link": lk.name, "type": lk.type, "a": lk.a, "b": lk.b, "host": host,
                      "a_end": f"(not reached: {answer.get('error')})"}
                     for lk in self.whole.links if self.place.tap_host(lk) == host]  # fmt: skip
        return rows


def host_lines(status: JsonObject) -> list[str]:
    """The hosts of a spread lab's status (`lab status`), each reached or not, with its
    devices; nothing for a lab on one machine."""
    hosts, devices, links = status.get("hosts"), status.get("devices"), status.get("links")
    if not isinstance(hosts, dict) or not isinstance(devices, dict) or not isinstance(links, dict):
        return []
    out = ["hosts:"]
    for name, host in hosts.items():
        state = "up" if host.get("up") else "starting" if host.get("reached") else \
            f"NOT REACHED ({host.get('error')})"  # fmt: skip
        alive = [n if d.get("alive") else f"{n}(down)" for n, d in devices.items()
                 if d.get("host") == name]  # fmt: skip
        out.append(f"  {name} {host.get('address')}: {state}; {' '.join(alive)}")
    down = [n for n, lk in links.items() if not lk.get("up")]
    out.append(f"links down: {' '.join(down)}" if down else "every link up")
    return out


def host_runner(
    lab: Lab, host: str, token_file: str | None, *, unpaced: bool = False, group: str = "none"
) -> HostRunner:
    """The runner of host `host`'s part of spread lab `lab` (`lab up --host`)."""
    placement = Placement(lab)
    view = placement.view(host)
    return HostRunner(view, unpaced=unpaced, group=group, placement=placement, here=host,
                      token_file=placement.token_file(host, token_file))  # fmt: skip
