"""Building a device object from its `ktcs-bench emulator` command line: one way for a device
process (`cli.emulator`) and for a lab run in one process (`lab.inprocess`), which builds each
device from the very arguments a live lab starts its process with (`lab.runner.device_args`).

`arguments(parser)` declares the options, `device_namespace(argv)` reads them, and
`build_device(args, lab)` makes the device of `args` in `lab` (a loaded lab file). Must not import
`lab` or `cli` (they stand above): the lab object is handed in.
"""

from __future__ import annotations

import argparse
import ssl
from dataclasses import dataclass
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.argtypes import host_port, positive
from ktcs_bench.errors import UsageError
from ktcs_bench.transport.endpoints import Endpoint, parse_links


def device_namespace(argv: list[str]) -> argparse.Namespace:
    """`ktcs-bench emulator` arguments (`lab.runner.device_args`) read as the command reads them:
    a lab in one process builds its devices from the same command lines a live lab starts."""
    p = argparse.ArgumentParser(prog="ktcs-bench emulator", add_help=False, exit_on_error=False)
    arguments(p)
    try:
        args, extra = p.parse_known_args(argv)
    except argparse.ArgumentError as exc:
        raise UsageError(f"emulator {' '.join(argv)}: {exc}") from None
    if extra:
        raise UsageError(f"emulator: unexpected arguments {' '.join(extra)}")
    return args


def arguments(p: argparse.ArgumentParser) -> None:
    """The options of `ktcs-bench emulator`."""
    p.add_argument("kind", choices=kinds.NAMES)
    p.add_argument("--lab", help="lab file or shipped lab name (default: the reference lab)")
    p.add_argument("--station", type=positive(int), help="station number (ixl, atc, trackside)")
    p.add_argument("--name", help="device name (default: KIND + station)")
    p.add_argument("--link", action="append", default=[], metavar="PEER=ENDPOINT")
    p.add_argument("--listen", type=host_port(any_free=True),
                   help="HOST:PORT to serve (ctc: Type II; trackcircuit: the rails)")  # fmt: skip
    p.add_argument("--control", type=host_port(any_free=True), default="127.0.0.1:0",
                   help="HOST:PORT of the JSON control port")  # fmt: skip
    p.add_argument(
        "--mode", choices=("center", "local"), help="ixl: start mode (default: the lab's)"
    )
    p.add_argument("--unpaced", action="store_true", help="Type I: no line-rate pacing")
    p.add_argument("--restarted", action="store_true",
                   help="ixl: restarted in a running lab (a crash recovery): start-up locking")  # fmt: skip
    p.add_argument("--train", help="train: the train id / scenario train to run")
    p.add_argument("--console", type=host_port(any_free=True), metavar="HOST:PORT",
                   help="ctc: serve the web console here")  # fmt: skip
    p.add_argument("--tap", action="append", default=[], help="ctc: a tap the console may monitor")
    p.add_argument(
        "--console-origin", action="append", default=[], metavar="ORIGIN",
        help="ctc: a web origin (e.g. http://ctc.lab:8020) whose pages may operate through the "
        "console, besides its own (repeatable)",
    )  # fmt: skip
    p.add_argument(
        "--fault", action="append", default=[], metavar="VARIANT",
        help="break one protocol rule on purpose, for the conformance suite to catch "
        "(see `ktcs-bench conformance --list-faults`)",
    )  # fmt: skip
    p.add_argument(
        "--allow-source", action="append", default=[], metavar="CIDR",
        help="ctc: admit Type II connections only from these addresses/networks (repeatable)",
    )  # fmt: skip
    p.add_argument("--tls-cert", help="Type II over TLS (profile type2-tls): our certificate (PEM)")
    p.add_argument("--tls-key", help="Type II over TLS: our private key (PEM)")
    p.add_argument(
        "--tls-ca", help="Type II over TLS: CA (PEM) the peer's certificate must chain to "
        "(ctc: client certificates are then required)",
    )  # fmt: skip
    p.add_argument("--tls-server-name", help="ixl: the name (or IP) in the CTC's certificate")
    p.add_argument(
        "--token-file", metavar="FILE",
        help="the token its control port requires, kept in FILE (mode 0600; made if missing); "
        "default: $KTCS_BENCH_TOKEN_FILE, else the user's token in the run folder",
    )  # fmt: skip
    p.add_argument(
        "--lifeline", type=int, metavar="FD",
        help="stop when this file descriptor (a pipe from the launcher) reaches end of file: "
        "the launcher is gone (`lab up` gives each device one)",
    )  # fmt: skip
    p.add_argument("-v", "--verbose", action="store_true", help="log every event to stderr")


def _roles(links: dict[str, Endpoint], lab_devices: dict[str, str]) -> dict[str, Endpoint]:
    """Peer names may be roles, kinds (`trackside` for its role `io`) or lab device names;
    return {role: endpoint}."""
    out = {}
    for peer, ep in links.items():
        role = kinds.link_role(peer) or kinds.link_role(lab_devices.get(peer, ""))
        if not role:
            raise UsageError(
                f"--link {peer}=...: unknown peer (use {', '.join(kinds.LINK_ROLES)}"
                " or a lab device)"
            )
        out[role] = ep
    return out


def tls_context(args: argparse.Namespace, server: bool) -> ssl.SSLContext | None:
    """The type2-tls context from --tls-cert/--tls-key/--tls-ca (None when none is given)."""
    cert, key, ca = args.tls_cert, args.tls_key, args.tls_ca
    if not (cert or key or ca):
        return None
    if server and not (cert and key):
        raise UsageError("a TLS server needs --tls-cert and --tls-key")
    if bool(cert) != bool(key):
        raise UsageError("--tls-cert and --tls-key go together")
    purpose = ssl.Purpose.CLIENT_AUTH if server else ssl.Purpose.SERVER_AUTH
    try:
        ctx = ssl.create_default_context(purpose, cafile=ca)
        if cert:
            ctx.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as exc:
        raise UsageError(f"TLS: {exc}") from None
    if server and ca:
        ctx.verify_mode = ssl.CERT_REQUIRED
    return ctx


def build_device(args: argparse.Namespace, lab: Any):  # type: ignore[no-untyped-def]
    """The device `args` describe, in `lab` (a `lab.topology.Lab`): built by its kind's builder
    (`kinds.KINDS`), one of the `build_KIND` functions below."""
    from ktcs_bench.type1 import LinkConfig

    line = lab.load_line()
    links = _roles(parse_links(args.link), {d.name: d.kind for d in lab.devices.values()})
    kind = kinds.KINDS.get(args.kind)
    if kind is None:
        raise UsageError(f"unknown kind {args.kind}")
    from ktcs_bench.emulator import variants

    faults = variants.check(getattr(args, "fault", []) or [], kind.name)
    name = args.name or (f"{kind.name}{args.station}" if args.station else kind.name)
    type1 = LinkConfig(
        line_rate=None if args.unpaced else lab.line_rate,
        longest_frame_data=lab.longest_frame_data,
    )
    if kind.station:
        if args.station is None:
            raise UsageError(f"emulator {kind.name} needs --station (one of {lab.stations})")
        if args.station not in line.stations:
            raise UsageError(
                f"station {args.station} is not on the line (stations {sorted(line.stations)})"
            )
    return kind.build(Build(name, args, lab, line, links, type1, faults))


@dataclass(frozen=True, slots=True)
class Build:
    """What a kind's builder is given: the device's name, its arguments, its lab and line, its
    links by role, its Type I settings and its protocol faults."""

    name: str
    args: argparse.Namespace
    lab: Any
    line: Any
    links: dict[str, Endpoint]
    type1: Any
    faults: frozenset[str]


def build_ixl(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.ixl import IxlDevice
    from ktcs_bench.ixl.modes import Mode

    args, lab = b.args, b.lab
    mode = Mode(args.mode or lab.ixl_mode)
    return IxlDevice(b.name, b.line, args.station, b.links, mode=mode, type1=b.type1,
                     type1_profile=lab.type1_profile, control=args.control, faults=b.faults,
                     ssl=tls_context(args, server=False),
                     server_hostname=args.tls_server_name,
                     restarted=args.restarted)  # fmt: skip


def build_atc(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.atc import AtcDevice

    return AtcDevice(b.name, b.line, b.args.station, b.links, type1=b.type1,
                     type1_profile=b.lab.type1_profile, control=b.args.control,
                     faults=b.faults)  # fmt: skip


def build_trackside(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.trackside import TracksideDevice

    return TracksideDevice(b.name, b.line, b.args.station, b.links, type1=b.type1,
                           type1_profile=b.lab.type1_profile, control=b.args.control,
                           faults=b.faults)  # fmt: skip


def build_trackcircuit(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.trackcircuit import TrackCircuitDevice

    return TrackCircuitDevice(b.name, b.line, b.args.listen or ("127.0.0.1", 0), b.args.control)


def build_ctc(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.ctc import CtcDevice

    args, lab = b.args, b.lab
    listen = args.listen or ("127.0.0.1", lab.type2_port)
    ars = lab.ars  # automatic route setting of the lab's timetable: the lab file's `ars:`
    return CtcDevice(b.name, b.line, lab.stations, listen, control=args.control,
                     console=args.console, console_origins=args.console_origin, taps=args.tap,
                     faults=b.faults, allowed_sources=args.allow_source or None,
                     ssl=tls_context(args, server=True),
                     timetable=lab.load_timetable(b.line) if ars else None,
                     ars_on=ars.start_on if ars else ())  # fmt: skip


def build_train(b: Build):  # type: ignore[no-untyped-def]
    from ktcs_bench.emulator.train import TrainDevice

    return TrainDevice.from_args(b.name, b.lab, b.line, b.links, b.args.train, b.args.control)
