"""`ktcs-bench monitor`: live decoded frames of a link (through its tap), an endpoint, or a capture."""

from __future__ import annotations

import argparse
import os
import socket
import time
from collections.abc import Iterator

import serial

from ktcs_bench.capture import CaptureRecord, open_writer, read_capture
from ktcs_bench.capture.printer import FramePrinter
from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.cli._common import duration, positive
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.station_codes.chart import CodeChart
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.core import TapEvent
from ktcs_bench.tap.recorder import Recorder
from ktcs_bench.transport.endpoints import parse_endpoint

HELP = "watch a link live: decoded frames, CRC verdicts and ARQ events (via its tap)"
DESCRIPTION = """\
Show every frame of a link as it passes: time, direction, the raw bytes in the console style of
seed 004 Fig. 7, the decoded fields, the CRC verdict ("Packet = [F1]-[E7], Cal = [F1]-[E7]") and
the ARQ events inferred from the frames (ACK/NAK, retransmission = the same SEQ seen twice, SEQ
gaps, bad frames a receiver must NAK).

SOURCE is one of
  a tap           its name (tap run --name), HOST:PORT or PORT of its control port, tap://...
  an endpoint     tcp://HOST:PORT (connect and show what it sends), or a serial device path / any
                  pyserial URL (a passive RS485 sniffer port, rfc2217://, socket://)
  a capture file  a hex log or .pcapng (offline, same display)
"""
EPILOG = """\
examples:
  ktcs-bench monitor st18-ixl-atc
  ktcs-bench monitor 127.0.0.1:40111 --json --write st18.pcapng
  ktcs-bench monitor tcp://127.0.0.1:5020 --profile ktcs-type2
  ktcs-bench monitor /dev/ttyUSB0 --baud 9600
  ktcs-bench monitor captures/st18.hex --chart code_charts/st18_atc_to_ixl.yaml
  ktcs-bench monitor iv1820 --chart ixl18=code_charts/st18_ixl_to_east.yaml \
      --chart ixl20=code_charts/st20_ixl_to_west.yaml

exit status: 0 done (Ctrl-C, the source ended, or --count frames seen); 1 --timeout passed before
--count frames; 2 bad arguments; 3 the tap or endpoint cannot be reached.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "monitor", help=HELP, description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    p.add_argument("source", metavar="TAP|ENDPOINT|FILE")
    p.add_argument(
        "--profile",
        help="frame profile (default: the tap's; ktcs-type2 for tcp://, ktcs-type1 otherwise)",
    )
    p.add_argument(
        "--chart", action="append", default=[], metavar="[SENDER=]CHART",
        help="code chart YAML: show code names; SENDER=CHART for the frames one end sends "
        "(a link carries a chart each way: --chart ixl18=st18_ixl_to_east.yaml "
        "--chart ixl20=st20_ixl_to_west.yaml; repeatable)",
    )  # fmt: skip
    p.add_argument(
        "--json", action="store_true", help="JSON lines: SPEC §7 keys + time, direction, arq"
    )
    p.add_argument("--write", action="append", default=[], metavar="CAPTURE",
                   help="also record to CAPTURE.hex or CAPTURE.pcapng (repeatable)")  # fmt: skip
    p.add_argument("--history", action="store_true", help="first show what the tap recorded before")
    p.add_argument("--count", type=positive(int), help="stop after this many frames")
    p.add_argument("--timeout", type=duration, help="stop after this many seconds")
    p.add_argument(
        "--baud", type=positive(int), default=9600, help="serial endpoint baud rate (9600)"
    )
    p.set_defaults(handler=run)


def _is_serial(source: str) -> bool:
    scheme = source.split("://", 1)[0] if "://" in source else ""
    if scheme:
        return scheme not in ("tcp", "tap", "listen")
    return source.startswith("/dev/") or (os.path.exists(source) and not os.path.isfile(source))


def _tap_records(
    source: str, history: bool, deadline: float | None, header: TapEvent
) -> Iterator[CaptureRecord | TapEvent]:
    with TapClient(source) as client:
        left = None if deadline is None else max(0.05, deadline - time.monotonic())
        events = client.subscribe(history=history, timeout=left)
        header.update(next(events))
        yield header
        for ev in events:
            if "hex" in ev:
                yield CaptureRecord(
                    ev.get("time"), str(ev.get("direction")), bytes.fromhex(ev["hex"])
                )
            else:
                yield ev


def _stream_records(
    source: str, profile: FrameProfile, baud: int, deadline: float | None
) -> Iterator[CaptureRecord]:
    """Frames of what an endpoint sends (direction `rx`), framed by a Recorder."""
    recorder = Recorder(profile)
    sock: socket.socket | None = None
    port: serial.Serial | None = None
    try:
        if source.startswith("tcp://"):
            ep = parse_endpoint(source)
            try:
                sock = socket.create_connection((ep.host, ep.port), timeout=5)
            except OSError as exc:
                raise PeerError(f"cannot connect to {source}: {exc}") from None
            sock.settimeout(0.05)
        else:
            try:
                port = serial.serial_for_url(source, baudrate=baud, timeout=0.05)
            except (serial.SerialException, ValueError) as exc:
                raise PeerError(f"cannot open {source}: {exc}") from None
        while deadline is None or time.monotonic() < deadline:
            data = b""
            try:
                if sock is not None:
                    data = sock.recv(65536)
                    if not data:
                        break
                elif port is not None:
                    data = port.read(max(1, port.in_waiting))  # returns at the first byte
            except TimeoutError:
                data = b""
            except (OSError, serial.SerialException) as exc:
                raise PeerError(f"{source}: {exc}") from None
            now = time.time()
            if data:
                yield from recorder.feed("rx", data, now)
            yield from recorder.handle_timer(now)
        yield from recorder.flush()
    finally:
        if sock is not None:
            sock.close()
        if port is not None:
            port.close()


def _charts(given: list[str]) -> tuple[CodeChart | None, dict[str, CodeChart]]:
    """`--chart` values: the chart of every frame (CHART), and the chart of the frames each
    named end sends (SENDER=CHART; a path holding "=" is a CHART when it is a file)."""
    every: CodeChart | None = None
    by_sender: dict[str, CodeChart] = {}
    for value in given:
        sender, _, path = value.partition("=")
        if not path or os.path.isfile(value):
            if every is not None:
                raise UsageError("--chart: one chart for every frame; SENDER=CHART for each end")
            every = load_chart(value)
        elif sender in by_sender:
            raise UsageError(f"--chart: two charts for the frames {sender} sends")
        else:
            by_sender[sender] = load_chart(path)
    return every, by_sender


def run(args: argparse.Namespace) -> int:
    chart, charts = _charts(args.chart)
    colour: bool = args.colour
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    source: str = args.source
    items: Iterator[CaptureRecord | TapEvent]
    profile: FrameProfile | None = get_profile(args.profile) if args.profile else None
    if os.path.isfile(source):
        capture = read_capture(source)
        if profile is None:
            from ktcs_bench.codec.vote import choose_profile

            data = b"".join(r.data for r in capture.records)
            profile = get_profile(capture.profile) if capture.profile else None
            if profile is None and data:
                profile = choose_profile(data, "auto")[0]
        items = iter(capture.records)
    elif _is_serial(source) or source.startswith("tcp://"):
        if profile is None:
            profile = get_profile("ktcs-type2" if source.startswith("tcp://") else "ktcs-type1")
        items = _stream_records(source, profile, args.baud, deadline)
    else:
        header: TapEvent = {}
        items = _tap_records(source, args.history, deadline, header)
        next(items)
        if profile is None:
            profile = get_profile(str(header.get("profile") or "ktcs-type1"))
        if not args.json:
            print(f"monitoring tap {header.get('tap') or source} ({header.get('kind')}, "
                  f"profile {profile.name}, ends {' & '.join(header.get('names', []))})", flush=True)  # fmt: skip
    if profile is None:
        raise UsageError(f"{source}: no frames to monitor")
    printer = FramePrinter(profile, chart=chart, charts=charts, colour=colour, as_json=args.json)
    writers = [open_writer(p, link=profile.protocol, profile=profile.name) for p in args.write]
    try:
        for item in items:
            if isinstance(item, dict):
                printer.event(item)
                continue
            for w in writers:
                w.write(item)
            printer.show(item)
            if args.count is not None and printer.frames >= args.count:
                return 0
            if deadline is not None and time.monotonic() >= deadline:
                break
    finally:
        for w in writers:
            w.close()
    return 1 if args.count is not None and printer.frames < args.count else 0
