"""`ktcs-bench replay`: send a capture's frames into a link and show (and check) what comes back."""

from __future__ import annotations

import argparse
import os
import queue
import select
import socket
import sys
import threading
import time
from typing import Any

import serial

from ktcs_bench.capture import (
    Capture,
    CaptureRecord,
    normalise_direction,
    open_writer,
    read_capture,
    reverse_direction,
)
from ktcs_bench.charts.files import load_chart
from ktcs_bench.cli._common import duration, positive
from ktcs_bench.cli.monitor import FramePrinter
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.tap.client import TapClient
from ktcs_bench.tap.recorder import Recorder
from ktcs_bench.tap.registry import tap_file
from ktcs_bench.transport.endpoints import parse_endpoint

HELP = "send captured frames into a pty, serial URL, TCP address or tap; show what comes back"
DESCRIPTION = """\
Replay the frames of a capture (a hex log, a .pcapng, or any hex text `decode` reads) into a link,
show every frame sent and every frame that comes back, decoded, and optionally record both and
compare the replies with an expected capture.

The frames sent are those of one direction of FILE (--send, default: the first direction in the
file); the replies are recorded with the reverse direction (a>b -> b>a, tx -> rx).

TARGET:
  /dev/pts/N, /dev/ttyUSB0, loop://, socket://H:P, rfc2217://H:P   a pty or any pyserial URL
  tcp://HOST:PORT                                                   connect over TCP
  NAME | tap://HOST:PORT                                            into a running tap: the frames
        are injected as if sent by one end (--send a>b, default the tap's first direction) and
        the other end's frames are the replies

--timing original  keep the capture's time between frames (at least; --max-gap S: a
                   silence longer than S seconds is cut to S)
         line      as fast as the line allows at --baud (default; 10 bits a byte); no pacing
                   over TCP unless --baud is given
         step      wait for a reply (or Enter, on a terminal) before each next frame
"""
EPILOG = """\
examples:
  ktcs-bench replay protocols/captures/fig7.hex --to /dev/pts/7 --profile ktcs-type1-fig7
  ktcs-bench replay st18.hex --to st18-ixl-atc --send ixl>atc --timing original
  ktcs-bench replay ident.hex --to tcp://127.0.0.1:5020 --record got.pcapng
  ktcs-bench replay requests.hex --to /dev/pts/7 --expect answers.hex   # exit 1 on a difference

exit status: 0 done (and the replies match --expect); 1 the replies differ from --expect (the first
difference is printed); 2 bad arguments or file; 3 the target cannot be opened or failed.
"""

QUIET_CAP = 10  # at the end, wait at most this many --wait periods while replies keep coming


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "replay", help=HELP, description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    p.add_argument("file", metavar="FILE", help="capture: hex log, .pcapng or hex text")
    p.add_argument("--to", required=True, metavar="TARGET", help="where to send (see above)")
    p.add_argument("--send", metavar="DIR", help="which direction of FILE to send (a>b, tx, ...)")
    p.add_argument("--timing", choices=("original", "line", "step"), default="line")
    p.add_argument(
        "--max-gap",
        type=duration,
        metavar="S",
        help="with --timing original: cap every silence between frames at S seconds",
    )
    p.add_argument(
        "--baud", type=positive(int), help="line rate for --timing line and serial ports (9600)"
    )
    p.add_argument("--wait", type=duration, default=1.0,
                   help="seconds of quiet that end the replay after the last frame (1.0); "
                   "also the step timeout off a terminal")  # fmt: skip
    p.add_argument("--record", action="append", default=[], metavar="FILE",
                   help="record what was sent and what came back (.hex or .pcapng)")  # fmt: skip
    p.add_argument("--expect", metavar="CAPTURE", help="compare the replies with this capture")
    p.add_argument("--profile", help="frame profile (default: the capture's, or auto)")
    p.add_argument("--chart", help="code chart YAML: show code names")
    p.add_argument(
        "--json", action="store_true", help="JSON lines (SPEC §7 keys + time, direction)"
    )
    p.add_argument("--quiet", action="store_true", help="do not print the frames")
    p.set_defaults(handler=run)


class ReplayTarget:
    """Where frames go; replies arrive framed, as capture records, on `replies`."""

    def __init__(self) -> None:
        self.replies: queue.Queue[CaptureRecord] = queue.Queue()
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)

    def _start(self, fn: Any) -> None:
        self._thread = threading.Thread(target=fn, daemon=True)
        self._thread.start()


class StreamTarget(ReplayTarget):
    """A pty, a pyserial URL, or a TCP address: a byte stream both ways."""

    def __init__(self, spec: str, profile: FrameProfile, reply_dir: str, baud: int) -> None:
        super().__init__()
        self.spec = spec
        self._sock: socket.socket | None = None
        self._port: serial.Serial | None = None
        self._recorder = Recorder(profile)
        self._reply_dir = reply_dir
        if spec.startswith("tcp://"):
            ep = parse_endpoint(spec)
            try:
                self._sock = socket.create_connection((ep.host, ep.port), timeout=5)
            except OSError as exc:
                raise PeerError(f"cannot connect to {spec}: {exc}") from None
            self._sock.settimeout(0.05)
        else:
            try:
                self._port = serial.serial_for_url(spec, baudrate=baud, timeout=0.05)
            except (serial.SerialException, ValueError) as exc:
                raise PeerError(f"cannot open {spec}: {exc}") from None
        self._start(self._read)

    def send(self, data: bytes) -> None:
        try:
            if self._sock is not None:
                self._sock.sendall(data)
            elif self._port is not None:
                self._port.write(data)
                self._port.flush()
        except (OSError, serial.SerialException) as exc:
            raise PeerError(f"{self.spec}: {exc}") from None

    def _read(self) -> None:
        while not self._stop.is_set():
            data = b""
            try:
                if self._sock is not None:
                    data = self._sock.recv(65536)
                    if not data:
                        self.errors.append("the peer closed the connection")
                        break
                elif self._port is not None:
                    data = self._port.read(
                        max(1, self._port.in_waiting)
                    )  # returns at the first byte
            except TimeoutError:
                pass
            except (OSError, serial.SerialException) as exc:
                self.errors.append(str(exc))
                break
            now = time.time()
            for rec in self._recorder.feed(self._reply_dir, data, now) if data else []:
                self.replies.put(rec)
            for rec in self._recorder.handle_timer(now):
                self.replies.put(rec)
        for rec in self._recorder.flush():
            self.replies.put(rec)

    def close(self) -> None:
        super().close()
        if self._sock is not None:
            self._sock.close()
        if self._port is not None:
            self._port.close()


class TapTarget(ReplayTarget):
    """A running tap: frames are injected with `send DIR HEX`; replies come from `subscribe`."""

    def __init__(self, spec: str, send_dir: str | None) -> None:
        super().__init__()
        self._ctl = TapClient(spec)
        self._sub = TapClient(spec)
        events = self._sub.subscribe(timeout=None)
        self.header = next(events)
        a, b = self.header["names"]
        dirs = (f"{a}>{b}", f"{b}>{a}")
        self.send_dir = send_dir if send_dir in dirs else dirs[0]
        self.reply_dir = reverse_direction(self.send_dir)
        self._events = events
        self._start(self._read)

    def send(self, data: bytes) -> None:
        self._ctl.command(f"send {self.send_dir} {data.hex()}")

    def _read(self) -> None:
        try:
            for ev in self._events:
                if ev.get("direction") == self.reply_dir and "hex" in ev:
                    self.replies.put(
                        CaptureRecord(ev.get("time"), self.reply_dir, bytes.fromhex(ev["hex"]))
                    )
        except (PeerError, OSError, ValueError) as exc:
            if not self._stop.is_set():
                self.errors.append(str(exc))

    def close(self) -> None:
        self._stop.set()
        self._sub.close()  # ends the subscription read
        self._ctl.close()
        super().close()


def _is_tap(spec: str) -> bool:
    if spec.startswith("tap://") or spec.startswith("tap:"):
        return True
    if "://" in spec or spec.startswith("/") or os.path.exists(spec):
        return False
    try:
        return tap_file(spec).is_file()
    except UsageError:
        return False


def frames_of(records: list[CaptureRecord], profile: FrameProfile) -> list[bytes]:
    """Each record split into frames (and garbage spans), as raw bytes, in order."""
    out: list[bytes] = []
    for r in records:
        dec = StreamDecoder(profile)
        out += [x.raw for x in dec.feed(r.data) + dec.close()]
    return out


def expected_replies(capture: Capture, send_dirs: tuple[str, ...]) -> list[CaptureRecord]:
    """The replies in an expected capture: its frames in the reverse of a sent direction, else
    every frame not in a sent direction (a capture of the replies alone)."""
    reverse = {reverse_direction(d) for d in send_dirs}
    if reverse & set(capture.directions):
        return [r for r in capture.records if r.direction in reverse]
    return [r for r in capture.records if r.direction not in send_dirs]


def first_difference(expected: list[bytes], got: list[bytes]) -> str | None:
    for k in range(max(len(expected), len(got))):
        e = expected[k] if k < len(expected) else None
        g = got[k] if k < len(got) else None
        if e == g:
            continue
        if e is None:
            assert g is not None
            return f"reply frame {k + 1}: not expected (the expected capture has {len(expected)}); got {g.hex(' ').upper()}"
        if g is None:
            return f"reply frame {k + 1}: missing (got {len(got)} replies); expected {e.hex(' ').upper()}"
        return (
            f"reply frame {k + 1} differs:\n  expected {e.hex(' ').upper()}\n"
            f"  got      {g.hex(' ').upper()}"
        )
    return None


def _choose_profile(
    args: argparse.Namespace, capture: Capture, header: dict[str, Any]
) -> FrameProfile:
    if args.profile:
        return get_profile(args.profile)
    if header.get("profile"):
        return get_profile(str(header["profile"]))
    if capture.profile:
        return get_profile(capture.profile)
    from ktcs_bench.cli.decode import choose_profile

    data = b"".join(r.data for r in capture.records)
    protocol = "type2" if args.to.startswith("tcp://") else "auto"
    return choose_profile(data, protocol)[0]


def _enter_pressed() -> bool:
    if not sys.stdin.isatty():
        return False
    ready, _, _ = select.select([sys.stdin], [], [], 0)
    if ready:
        sys.stdin.readline()
        return True
    return False


def run(args: argparse.Namespace) -> int:
    if args.max_gap is not None:
        if args.timing != "original":
            raise UsageError("--max-gap caps the capture's gaps: it goes with --timing original")
    capture = read_capture(args.file)
    if not capture.records:
        raise UsageError(f"{args.file}: no frames in it")
    send_dir = normalise_direction(args.send) if args.send else capture.directions[0]
    to_send = [r for r in capture.records if r.direction == send_dir]
    if not to_send:
        raise UsageError(f"{args.file} has no frames in direction {send_dir} "
                         f"(it has {', '.join(capture.directions)})")  # fmt: skip
    expect = read_capture(args.expect) if args.expect else None
    header: dict[str, Any] = {}
    target: ReplayTarget
    if _is_tap(args.to):
        spec = args.to.removeprefix("tap://").removeprefix("tap:")
        tap_target = TapTarget(spec, send_dir)
        header = tap_target.header
        target, out_dir, reply_dir = tap_target, tap_target.send_dir, tap_target.reply_dir
    else:
        out_dir, reply_dir = send_dir, reverse_direction(send_dir)
        target = StreamTarget(args.to, _choose_profile(args, capture, {}), reply_dir,
                              args.baud or 9600)  # fmt: skip
    try:
        profile = _choose_profile(args, capture, header)
        printer = FramePrinter(
            profile, chart=load_chart(args.chart) if args.chart else None,
            colour=args.colour, as_json=args.json,
        )  # fmt: skip
        writers = [open_writer(p, link=profile.protocol, profile=profile.name) for p in args.record]
        replies: list[CaptureRecord] = []

        def take(rec: CaptureRecord) -> None:
            replies.append(rec)
            for w in writers:
                w.write(rec)
            if not args.quiet:
                printer.show(rec, "  (reply)")

        def pump(until: float) -> int:
            got = 0
            while True:
                left = until - time.monotonic()
                try:
                    rec = target.replies.get(timeout=max(0.0, min(left, 0.05)))
                except queue.Empty:
                    if left <= 0:
                        return got
                    continue
                take(rec)
                got += 1

        pace = args.baud or (None if args.to.startswith("tcp://") or header else 9600)
        start = time.monotonic()
        line_free = start
        last_time = to_send[0].time  # --timing original: each frame follows the one before
        last_sent = start  # by the capture's gap (capped at --max-gap), never less
        for k, rec in enumerate(to_send):
            if args.timing == "original" and rec.time is not None and last_time is not None:
                gap = max(0.0, rec.time - last_time)
                pump(last_sent + (gap if args.max_gap is None else min(gap, args.max_gap)))
                last_time = rec.time
            elif args.timing == "line":
                pump(line_free)
            elif args.timing == "step" and k > 0:
                wait_until = None if sys.stdin.isatty() else time.monotonic() + args.wait
                while not pump(time.monotonic() + 0.05) and not _enter_pressed():
                    if wait_until is not None and time.monotonic() >= wait_until:
                        break
            if target.errors:
                raise PeerError(f"{args.to}: {target.errors[0]}")
            target.send(rec.data)
            last_sent = time.monotonic()
            sent = CaptureRecord(time.time(), out_dir, rec.data)
            for w in writers:
                w.write(sent)
            if not args.quiet:
                printer.show(sent, "  (sent)")
            if pace:
                line_free = max(line_free, time.monotonic()) + len(rec.data) * 10 / pace
        for _ in range(QUIET_CAP):
            if not pump(time.monotonic() + args.wait):
                break
        for w in writers:
            w.close()
    finally:
        target.close()
    if not args.quiet and not args.json:
        print(
            f"replay: {len(to_send)} frames sent ({out_dir}), {len(replies)} replies ({reply_dir})"
        )
    if expect is not None:
        want = frames_of(expected_replies(expect, (send_dir, out_dir)), profile)
        got = frames_of(replies, profile)
        diff = first_difference(want, got)
        if diff is not None:
            print(f"replay: replies differ from {args.expect}: {diff}", file=sys.stderr)
            return 1
        if not args.json:
            print(f"replay: the {len(got)} replies match {args.expect}")
    return 0
