"""The lab file: devices (kind, station, host), Type I / Type II links and whether a tap sits in
each, the line they run on, the link settings, the lab's timetable and whether the CTC's
automatic route setting runs it (`ars:`, the stations where it starts on). Every problem is a
ConfigError naming the file, the key path and what is wrong.

A device may be external -- a real one the lab does not run, linked through its link's tap:
    atc18: {kind: atc, station: 18, external: {serial: "rfc2217://10.0.0.2:4000"}}
    ixl22: {kind: ixl, station: 22, external: {address: "0.0.0.0:6000"}}
Type I devices (atc, trackside) give `serial`, a device path or any pyserial URL the tap opens,
or `labgrid: PLACE`, a place of a labgrid coordinator that `lab up` acquires for the lab's life
(`LabgridPlace`; `lab.labgrid`) and whose exported serial port it opens;
a CTC gives `address`, where the taps connect to it; an IXL gives `address`, where the tap serves
it (the real IXL is set to connect there; its own Type I peers are its business, not the lab's).
An external ATC or trackside is off the lab's rails unless `rails: true` says it joins them itself
(then the track-circuit emulator needs a fixed port, so the device can be told where they are).

A lab may spread over several computers (SPEC §10, docs/multihost.md): `hosts:` names them
(NAME -> {address, control: PORT}, `lab.hosts`) and each device's `host:` names one (or gives
one's address); `lab up --host NAME` runs the devices placed there (`lab.multihost`).

Adjacent stations' IXLs are linked by a vital Type I link (SPEC §6.6), one per interval between
them that is not a lab edge:
    - {name: iv1820, type: type1, a: ixl18, b: ixl20, tap: true}
Both ends are IXLs of the lab (not external) at the two ends of one interval of the line, and the
link goes through its tap. The IXL at the interval's west end (`Interval.west`) is given its
neighbour as `--link east=...`, the other `--link west=...` (`LinkSpec.roles`); each sends its
`ixl_to_ROLE` chart and reads `ROLE_to_ixl`. Type I is symmetric: each end asks for the other's
full state when the link comes up, neither is primary, so `a` and `b` only name the tap's ends
(its directions `a>b`, `b>a`); the shipped and generated labs put the west end first."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import msgspec
import serial

from ktcs_bench import kinds
from ktcs_bench.datafiles import data_dir, load_mapping
from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.lab.hosts import HostSpec, device_address, parse_hosts
from ktcs_bench.lab.labgrid import LABGRID_PORT, LabgridPlace
from ktcs_bench.schema import Shape, convert, located
from ktcs_bench.station.loader import load_line
from ktcs_bench.station.model import Line
from ktcs_bench.station.timetable import Timetable, load_timetable
from ktcs_bench.transport.endpoints import check_port, parse_endpoint, parse_host_port

_ORIGIN = re.compile(r"https?://[^/\s:]+(:\d{1,5})?/?|https?://\[[0-9a-fA-F:]+\](:\d{1,5})?/?")
_HOST_PORT_URL = re.compile(r"(rfc2217|socket)://([^/?]*)")  # pyserial URLs that name HOST:PORT


@dataclass(frozen=True)
class External:
    """A real device the lab does not run, reached through its link's tap: at `serial` (a device
    path or pyserial URL: Type I; for a `labgrid` place, its exported port once acquired) or at
    `address` (HOST:PORT: where a CTC serves, or where the tap serves an IXL). `rails`: an ATC or
    trackside that joins the lab's rails itself."""

    serial: str | None = None
    address: tuple[str, int] | None = None
    rails: bool = False
    labgrid: LabgridPlace | None = None

    @property
    def endpoint(self) -> str:
        if self.address is not None:
            return f"tcp://{self.address[0]}:{self.address[1]}"
        if self.labgrid is not None:  # its exported port, once lab up has acquired it
            place = f"labgrid place {self.labgrid.place}"
            return place if self.serial is None else f"{self.serial} ({place})"
        return str(self.serial)


@dataclass(frozen=True)
class DeviceSpec:
    name: str
    kind: str
    station: int | None = None
    host: str = "127.0.0.1"
    options: dict[str, Any] = field(default_factory=dict)
    external: External | None = None  # a real device: the lab links it, does not run it


@dataclass(frozen=True)
class LinkSpec:
    name: str
    type: str  # type1 | type2
    a: str  # the IXL
    b: str  # its peer
    tap: bool = True
    interval: str | None = None
    """A link between neighbouring IXLs (SPEC §6.6): the interval they share."""
    roles: tuple[str, str] | None = None
    """Such a link's roles: what a calls b and what b calls a (`kinds.EAST`/`WEST`: the IXL at
    the interval's west end calls the other `east`)."""


@dataclass(frozen=True)
class ArsSpec:
    """The lab file's `ars:` section: the CTC runs automatic route setting from the lab's
    timetable (`timetable:`), on at the stations `start_on` at start and off at the others."""

    start_on: tuple[int, ...]


ARS_KEYS = ("start_on",)  # _ArsShape's


@dataclass(frozen=True)
class Lab:
    name: str
    file: Path
    line_file: Path
    devices: dict[str, DeviceSpec]
    links: tuple[LinkSpec, ...]
    type1_profile: str = "ktcs-type1"
    line_rate: float | None = 9600.0
    longest_frame_data: int | None = 132
    type2_profile: str = "ktcs-type2"
    type2_port: int = 0
    console_port: int | None = None
    console_origins: tuple[str, ...] = ()  # web origins besides its own whose pages may operate
    ixl_mode: str = "center"
    timetable_file: Path | None = None  # the lab's one timetable: its trains, ARS's routes
    ars: ArsSpec | None = None  # None: no `ars:` section, the operator sets every route
    hosts: dict[str, HostSpec] = field(default_factory=dict)  # `hosts:` (lab.hosts): spread labs

    def of_kind(self, kind: str) -> list[DeviceSpec]:
        return [d for d in self.devices.values() if d.kind == kind]

    def ours(self, kind: str) -> list[DeviceSpec]:
        """The devices of `kind` the lab runs (not external)."""
        return [d for d in self.of_kind(kind) if d.external is None]

    @property
    def stations(self) -> list[int]:
        return sorted(d.station for d in self.of_kind(kinds.IXL) if d.station is not None)

    def links_of(self, device: str) -> list[LinkSpec]:
        return [lk for lk in self.links if device in (lk.a, lk.b)]

    def peer_role(self, link: LinkSpec, device: str) -> str:
        """The role the other end plays for `device` (ctc, atc, io, ixl; east or west across an
        interval)."""
        if link.roles is not None:
            return link.roles[0] if device == link.a else link.roles[1]
        other = link.b if link.a == device else link.a
        return kinds.role_of(self.devices[other].kind)

    def load_line(self) -> Line:
        return load_line(self.line_file)

    def load_timetable(self, line: Line | None = None) -> Timetable | None:
        """The lab's timetable checked against its line (None: the lab has none)."""
        if self.timetable_file is None:
            return None
        return load_timetable(self.timetable_file, line or self.load_line())


def default_lab_path() -> Path:
    return data_dir("emulators") / "labs" / "reference.yaml"


def resolve_lab_path(name: str | None) -> Path:
    """A lab by path, or by name from the shipped `emulators/labs/`."""
    if name is None:
        return default_lab_path()
    p = Path(name)
    if p.is_file():
        return p
    shipped = data_dir("emulators") / "labs" / f"{name}.yaml"
    if shipped.is_file():
        return shipped
    raise ConfigError(name, "", "no such lab file (and no shipped lab of that name)")


class _Type1Shape(Shape):
    """The lab file's `type1:` (the numbers' bounds are checked in code, in their own words)."""

    profile: str = "ktcs-type1"
    line_rate: Any = 9600.0  # bit/s; null: unpaced
    longest_frame_data: Any = 132  # null: the profile's maximum DATA length


class _Type2Shape(Shape):
    """The lab file's `type2:`."""

    profile: str = "ktcs-type2"
    port: Any = None  # the CTC's Type II port (0: any free port)


class _ConsoleShape(Shape):
    """The lab file's `console:`."""

    port: Any = None
    origins: tuple[str, ...] | None = None  # web origins besides its own whose pages may operate


class _LabShape(Shape):
    """The lab file's top level: a key no reader knows is refused. The sections' settings are
    converted on their own, after their type is checked in the words the tests know."""

    lab: str | int | float
    line: str
    devices: Any
    links: Any
    description: str | None = None
    timetable: str | None = None
    ixl_mode: Any = "center"
    ars: Any = None
    type1: Any = None
    type2: Any = None
    console: Any = None
    hosts: Any = None


_SECTIONS = ("type1", "type2", "console")


def load_lab(path: str | Path | None = None) -> Lab:
    file = Path(path) if path is not None else default_lab_path()
    raw = load_mapping(file, "lab")

    def fail(place: str, problem: str) -> ConfigError:
        return located(file, place, problem)

    for key in _SECTIONS:  # a section's type before the file's keys (its message is known)
        section = raw.get(key) or {}
        if not isinstance(section, dict):
            raise fail(key, f"must be a mapping of settings, not {excerpt(section)}")
    top = convert(raw, _LabShape, file)
    line_file = (file.parent / top.line).resolve()
    if not line_file.is_file():
        raise fail("line", f"no such line file: {line_file}")
    devices = _devices(top.devices, file, fail)
    hosts = parse_hosts(top.hosts, file, fail)
    for name, raw_device in top.devices.items():  # `host:` names one of `hosts:` (lab.hosts)
        address = device_address(raw_device.get("host"), hosts, f"devices.{name}.host", fail)
        if address is not None:
            devices[str(name)] = replace(devices[str(name)], host=address)
    links = _links(top.links, devices, file, fail)
    t1 = convert(top.type1 or {}, _Type1Shape, file, "type1")
    t2 = convert(top.type2 or {}, _Type2Shape, file, "type2")
    console = convert(top.console or {}, _ConsoleShape, file, "console")
    origins = console.origins or ()
    if not all(_ORIGIN.fullmatch(o) for o in origins):
        raise fail("console.origins", "a list of web origins, e.g. [http://ctc.lab:8020]")
    timetable_file = None
    if top.timetable is not None:
        timetable_file = (file.parent / top.timetable).resolve()
        if not timetable_file.is_file():
            raise fail("timetable", f"no such timetable file: {timetable_file}")
    mode = top.ixl_mode
    if mode not in ("center", "local"):
        raise fail("ixl_mode", f"must be center or local, not {excerpt(mode)}")
    lab = Lab(
        name=str(top.lab),
        file=file.resolve(),
        line_file=line_file,
        devices=devices,
        links=tuple(links),
        type1_profile=t1.profile,
        line_rate=_number(t1.line_rate, 9600.0, "type1.line_rate", fail),  # null: unpaced
        # null: the profile's maximum DATA length
        longest_frame_data=_whole(
            _number(t1.longest_frame_data, 132, "type1.longest_frame_data", fail)
        ),
        type2_profile=t2.profile,
        type2_port=_port(t2.port, "type2.port", fail) or 0,
        console_port=_port(console.port, "console.port", fail),
        console_origins=tuple(origins),
        ixl_mode=mode,
        timetable_file=timetable_file,
        hosts=hosts,
    )
    _check_lab(lab, fail)
    lab = replace(lab, links=_neighbour_links(lab, fail))
    if top.ars is not None:
        lab = replace(lab, ars=_ars(top.ars, lab, file, fail))
    return lab


_Fail = Callable[[str, str], ConfigError]


def _port(value: object, place: str, fail: _Fail) -> int | None:
    """A port the lab serves on: 0..65535 (0: any free port), or None when not given."""
    try:
        return None if value is None else check_port(value, any_free=True)
    except UsageError as exc:
        raise fail(place, str(exc)) from None


def _number(given: object, default: float, place: str, fail: _Fail) -> float | None:
    """A positive setting (a rate, a size; absent: `default`), whole where the default is;
    null stays None."""
    if given is None:
        return None
    whole = isinstance(default, int)
    value = given
    if isinstance(value, bool) or not isinstance(value, int if whole else (int, float)):
        value = None
    if value is None or not math.isfinite(value) or value <= 0:
        what = "a positive whole number" if whole else "a positive number"
        raise fail(place, f"must be {what}, not {excerpt(given)}")
    return float(value)


def _whole(value: float | None) -> int | None:
    return None if value is None else int(value)


class _DeviceShape(msgspec.Struct):
    """The keys of a device every kind knows; the others are its kind's options, free-form."""

    kind: str
    station: int | None = None  # a station's kinds need its number
    host: str = "127.0.0.1"
    external: Any = None  # a real device: its shape hangs on its kind (_SerialShape, _AddressShape)


_DEVICE_KEYS = frozenset(_DeviceShape.__struct_fields__)


def _devices(section: object, file: Path, fail: _Fail) -> dict[str, DeviceSpec]:
    """The lab file's `devices:` (NAME -> {kind, station, host, external, options...})."""
    devices: dict[str, DeviceSpec] = {}
    if not isinstance(section, dict) or not section:
        raise fail("devices", "must be a mapping NAME -> {kind, station, host}")
    for dname, spec in section.items():
        name = str(dname)
        place = f"devices.{name}"
        if not isinstance(spec, dict):
            raise fail(place, "must be a mapping with at least 'kind'")
        kind = spec.get("kind")
        if kind not in kinds.KINDS:
            raise fail(
                f"{place}.kind", f"must be one of {', '.join(kinds.NAMES)}, not {excerpt(kind)}"
            )
        known = convert(spec, _DeviceShape, file, place)
        station = known.station
        if kinds.KINDS[kind].station and station is None:
            raise fail(f"{place}.station", f"a {kind} needs its station number")
        options = {k: v for k, v in spec.items() if k not in _DEVICE_KEYS}
        if "port" in options:
            options["port"] = _port(options["port"], f"{place}.port", fail)
        external = None
        if "external" in spec:
            external = _external(known.external, kind, f"{place}.external", file, fail)
        devices[name] = DeviceSpec(name, kind, station, known.host, options, external)
    for kind in (k.name for k in kinds.KINDS.values() if k.single):
        count = sum(1 for d in devices.values() if d.kind == kind)
        if count > 1:
            raise fail("devices", f"at most one {kind} device, found {count}")
    return devices


class _LinkShape(Shape):
    """One entry of the lab file's `links:`."""

    name: str | int
    type: str | int  # type1 or type2: checked with the ends
    a: str | int  # the IXL
    b: str | int  # its peer
    tap: bool = True


def _links(
    section: object, devices: dict[str, DeviceSpec], file: Path, fail: _Fail
) -> list[LinkSpec]:
    """The lab file's `links:`, each from an IXL to a peer of its station, one per role."""
    links: list[LinkSpec] = []
    seen: dict[tuple[str, str], str] = {}
    for i, lk in enumerate(convert(section, tuple[_LinkShape, ...], file, "links")):
        place = f"links[{i}]"
        for end, device in (("a", lk.a), ("b", lk.b)):
            if str(device) not in devices:
                raise fail(f"{place}.{end}", f"unknown device {excerpt(device)}")
        a, b = str(lk.a), str(lk.b)
        if devices[b].kind == kinds.IXL:  # neighbouring IXLs: checked against the line later
            _check_neighbour_link(lk, place, devices[a], devices[b], fail)
            links.append(LinkSpec(str(lk.name), str(lk.type), a, b, lk.tap))
            continue
        _check_link(lk, place, devices[a], devices[b], fail)
        role_key = (a, kinds.role_of(devices[b].kind))
        if role_key in seen:
            raise fail(place, f"{a} already has a {role_key[1]} link ({seen[role_key]})")
        seen[role_key] = str(lk.name)
        links.append(LinkSpec(str(lk.name), str(lk.type), a, b, lk.tap))
    return links


def _check_link(lk: _LinkShape, place: str, ixl: DeviceSpec, peer: DeviceSpec, fail: _Fail) -> None:
    """One link's ends: an IXL (not an external one on Type I, nor without a tap) and a peer
    the link's type reaches, of the IXL's station."""
    a, b, typ = ixl.name, peer.name, lk.type
    if ixl.kind != kinds.IXL:
        raise fail(f"{place}.a", "end a of every link is an IXL")
    if ixl.external is not None and typ == "type1":
        raise fail(f"{place}.a", f"{a} is external: its Type I peers are its own, not the "
                   "lab's (list only its Type II link)")  # fmt: skip
    if ixl.external is not None and not lk.tap:
        raise fail(f"{place}.tap", f"{a} is external: the link's tap serves the address it "
                   "connects to, so the tap must be there (tap: true)")  # fmt: skip
    allowed = tuple(k.name for k in kinds.IXL_PEERS if k.link == typ)
    if typ not in (kinds.TYPE1, kinds.TYPE2):
        raise fail(f"{place}.type", f"must be type1 or type2, not {excerpt(typ)}")
    if peer.kind not in allowed:
        raise fail(
            f"{place}.b",
            f"a {typ} link from an IXL goes to {' or '.join(allowed)}, not a {peer.kind}",
        )
    if kinds.KINDS[peer.kind].station and peer.station != ixl.station:
        raise fail(f"{place}.b", f"{b} belongs to station {peer.station}, {a} to {ixl.station}")


def _check_neighbour_link(
    lk: _LinkShape, place: str, a: DeviceSpec, b: DeviceSpec, fail: _Fail
) -> None:
    """A link between two IXLs (SPEC §6.6), before the line is read: Type I, both IXLs ours,
    through a tap."""
    name = str(lk.name)
    if a.kind != kinds.IXL:
        raise fail(f"{place}.a", "end a of every link is an IXL")
    if lk.type != kinds.TYPE1:
        raise fail(f"{place}.type", f"link {name} between IXLs {a.name} and {b.name} is a vital "
                   f"Type I link (type: type1), not {excerpt(lk.type)}")  # fmt: skip
    for end, d in (("a", a), ("b", b)):
        if d.external is not None:
            raise fail(f"{place}.{end}", f"link {name}: {d.name} is external: its Type I peers "
                       "are its own, not the lab's")  # fmt: skip
    if not lk.tap:
        raise fail(f"{place}.tap", f"link {name} between IXLs {a.name} and {b.name} goes "
                   "through its tap (tap: true): each IXL opens its end, neither makes a pty "
                   "for the other")  # fmt: skip


def _neighbour_links(lab: Lab, fail: _Fail) -> tuple[LinkSpec, ...]:
    """The lab's links with each link between two IXLs given its interval and its ends' roles:
    the two IXLs' stations are the ends of one interval of the line that is not a lab edge, and
    each IXL has at most one link to each side."""
    line = lab.load_line()
    out: list[LinkSpec] = []
    seen: dict[tuple[str, str], str] = {}
    for i, lk in enumerate(lab.links):
        a, b = lab.devices[lk.a], lab.devices[lk.b]
        if b.kind != kinds.IXL:
            out.append(lk)
            continue
        ends = {a.station, b.station}
        shared = [iv for iv in line.intervals if {iv.west, iv.east} == ends and not iv.boundary]
        if not shared:
            raise fail(f"links[{i}]", f"link {lk.name}: stations {a.station} ({a.name}) and "
                       f"{b.station} ({b.name}) share no interval of the line {line.name} "
                       "(a link between IXLs joins adjacent stations)")  # fmt: skip
        iv = shared[0]
        roles = (
            kinds.neighbour_role(a.station == iv.west),
            kinds.neighbour_role(b.station == iv.west),
        )
        for device, role in ((a.name, roles[0]), (b.name, roles[1])):
            if (device, role) in seen:
                raise fail(f"links[{i}]", f"link {lk.name}: {device} already has its {role} "
                           f"neighbour link ({seen[device, role]})")  # fmt: skip
            seen[device, role] = lk.name
        out.append(replace(lk, interval=iv.name, roles=roles))
    return tuple(out)


def _check_lab(lab: Lab, fail: _Fail) -> None:
    """The lab as a whole: external devices on the rails can be told where they are; every
    station is on the line; every train device's train is in the timetable."""
    for d in lab.devices.values():
        if d.external is not None and d.external.rails:
            tc = lab.of_kind(kinds.TRACKCIRCUIT)
            if not tc or tc[0].external is not None or not tc[0].options.get("port"):
                raise fail(f"devices.{d.name}.external.rails", "a device that joins the lab's "
                           "rails itself must be told where they are before the lab starts: give "
                           "the track-circuit emulator a port (tc: {kind: trackcircuit, port: N})")  # fmt: skip
    line = lab.load_line()
    for d in lab.devices.values():
        if d.station is not None and d.station not in line.stations:
            raise fail(
                f"devices.{d.name}.station", f"station {d.station} is not on the line {line.name}"
            )
    timetable = lab.load_timetable(line)
    for d in lab.of_kind(kinds.TRAIN):
        if timetable is None or kinds.TRAIN not in d.options:
            continue
        train = str(d.options[kinds.TRAIN])
        if train not in {t.id for t in timetable.trains}:
            raise fail(
                f"devices.{d.name}.train",
                f"train {excerpt(train)} is not in the timetable {timetable.file} "
                f"({', '.join(t.id for t in timetable.trains)})",
            )


class _SerialShape(Shape):
    """An external Type I device (atc, trackside): where its serial port is, or the labgrid place
    that exports it (`LabgridPlace`)."""

    serial: str | None = None
    labgrid: str | None = None
    coordinator: str | None = None  # with labgrid
    resource: str | None = None  # with labgrid
    rails: bool = False  # it joins the lab's rails itself


class _AddressShape(Shape):
    """An external CTC or IXL: where it serves, or where the tap serves it."""

    address: str


def _external(raw: Any, kind: str, place: str, file: Path, fail: _Fail) -> External:
    """A device's `external` mapping, checked: the key for its kind, a usable endpoint."""
    key = kinds.KINDS[kind].external
    if key is None:
        can = "; ".join(f"{', '.join(kinds.externals(k))}: {k}" for k in ("serial", "address"))
        raise fail(place, f"a {kind} cannot be external ({can})")
    if not isinstance(raw, dict):
        raise fail(place, f"must be a mapping, e.g. {{{key}: {_EXAMPLE[key]}}}")
    if key == "address":  # a CTC is connected to; an IXL is served (0: any free port)
        address = convert(raw, _AddressShape, file, place).address
        _text(address, f"{place}.address", fail)
        try:
            return External(address=parse_host_port(address, any_free=kind == kinds.IXL))
        except UsageError as exc:
            raise fail(f"{place}.address", str(exc)) from None
    shape = convert(raw, _SerialShape, file, place)
    if shape.serial is None and shape.labgrid is None:
        raise fail(f"{place}.serial", f"missing key: the serial port ({_EXAMPLE['serial']}) or "
                   f"the labgrid place that exports it (labgrid: {_EXAMPLE['labgrid']})")  # fmt: skip
    if shape.serial is not None and shape.labgrid is not None:
        raise fail(f"{place}.labgrid", "serial or labgrid, not both: a labgrid place's serial "
                   "port is the one its exporter serves")  # fmt: skip
    if shape.labgrid is not None:
        return External(labgrid=_labgrid_place(shape, place, fail), rails=shape.rails)
    for key in ("coordinator", "resource"):
        if getattr(shape, key) is not None:
            raise fail(f"{place}.{key}", "goes with a labgrid place (labgrid: PLACE)")
    assert shape.serial is not None
    _text(shape.serial, f"{place}.serial", fail)
    return External(
        serial=_serial_url(shape.serial.strip(), f"{place}.serial", fail), rails=shape.rails
    )


def _labgrid_place(shape: _SerialShape, place: str, fail: _Fail) -> LabgridPlace:
    """`labgrid: PLACE` with its optional `coordinator` (HOST or HOST:PORT) and `resource`."""
    assert shape.labgrid is not None
    for key in ("labgrid", "coordinator", "resource"):
        value = getattr(shape, key)
        if value is not None and (not value.strip() or value.strip() != value or "\n" in value):
            raise fail(f"{place}.{key}", f"must be a name without spaces around it, e.g. "
                       f"{_EXAMPLE[key]}, not {excerpt(value)}")  # fmt: skip
    coordinator = shape.coordinator
    if coordinator is not None:
        try:
            host, port = parse_host_port(
                coordinator if ":" in coordinator else f"{coordinator}:{LABGRID_PORT}"
            )
        except UsageError as exc:
            raise fail(f"{place}.coordinator", str(exc)) from None
        coordinator = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    return LabgridPlace(shape.labgrid, coordinator, shape.resource)


def _text(value: str, place: str, fail: _Fail) -> None:
    if not value.strip():
        key = place.rsplit(".", 1)[-1]
        raise fail(place, f"must be text, e.g. {_EXAMPLE[key]}, not {excerpt(value)}")


_EXAMPLE = {"serial": '"/dev/ttyUSB0" or "rfc2217://10.0.0.2:4000"', "address": '"10.0.0.5:6000"',
            "labgrid": "atc18-rack2", "coordinator": '"10.0.0.9:20408"', "resource": "serial0"}  # fmt: skip


def _serial_url(text: str, place: str, fail: _Fail) -> str:
    """A device path or a pyserial URL whose scheme pyserial knows (and whose HOST:PORT, for
    rfc2217:// and socket://, is one), not `pty` or a TCP endpoint of ours."""
    try:
        kind = parse_endpoint(text).kind
    except UsageError:
        kind = "tcp"
    if kind != "serial":
        raise fail(place, f"the real device's serial port or a pyserial URL, not {excerpt(text)}")
    try:
        serial.serial_for_url(text, do_not_open=True)
    except (ValueError, serial.SerialException) as exc:
        raise fail(place, f"{excerpt(text)}: {exc}") from None
    match = _HOST_PORT_URL.match(text)
    if match:
        try:
            parse_host_port(match.group(2), f"{text}")
        except UsageError as exc:
            raise fail(place, str(exc)) from None
    return text


class _ArsShape(Shape):
    """The lab file's `ars:` (its unknown keys are refused first, in words that name the one
    it takes: a boolean key is `on:` read by YAML)."""

    start_on: Any = "all"  # a list of the lab's stations, or all


def _ars(section: object, lab: Lab, file: Path, fail: _Fail) -> ArsSpec:
    """The `ars:` section, ARS in the CTC from the lab's `timetable:` -- `start_on`: the stations
    where it starts on (a list of the lab's stations, or `all`, the default; the others start
    off). Not `on:`: YAML reads that key as true."""
    if not isinstance(section, dict):
        raise fail("ars", "must be a mapping {start_on: [STATION, ...] | all}")
    for key in section:
        if isinstance(key, bool):  # on: / yes: / off: read as a boolean key
            raise fail(f"ars.{str(key).lower()}", "YAML reads this key as a boolean: the "
                       "stations where ARS starts on are `start_on`")  # fmt: skip
        if key not in ARS_KEYS:
            raise fail(f"ars.{key}", f"unknown key (ars takes {', '.join(ARS_KEYS)})")
    on = convert(section, _ArsShape, file, "ars").start_on
    if not lab.ours(kinds.CTC):
        raise fail("ars", "the lab runs no CTC to set routes (an external CTC sets its own)")
    if lab.timetable_file is None:
        raise fail("ars", "ARS sets the routes of the lab's timetable: give it (timetable: FILE)")
    if on == "all":
        stations = tuple(lab.stations)
    elif isinstance(on, list):
        for i, st in enumerate(on):
            if isinstance(st, bool) or not isinstance(st, int) or st not in lab.stations:
                raise fail(
                    f"ars.start_on[{i}]",
                    f"must be a station of the lab {lab.stations}, not {excerpt(st)}",
                )
        stations = tuple(sorted(set(on)))
    else:
        raise fail("ars.start_on", f"a list of the lab's stations, or all; not {excerpt(on)}")
    return ArsSpec(stations)
