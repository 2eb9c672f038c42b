"""`ktcs-bench replay`: send a capture's frames into a link and show (and check) what comes back.

Argument parsing and printing over the library (`ktcs_bench.replay`: the targets, the pacing, the
comparison with an expected capture)."""

from __future__ import annotations

import argparse
import select
import sys
from collections.abc import Callable, Mapping

from ktcs_bench.capture import (
    CaptureRecord,
    normalise_direction,
    open_writer,
    read_capture,
    reverse_direction,
)
from ktcs_bench.capture.printer import FramePrinter
from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.cli._common import duration, positive
from ktcs_bench.errors import UsageError
from ktcs_bench.replay import (
    Replay,
    ReplayTarget,
    StreamTarget,
    TapTarget,
    capture_profile,
    compare,
    is_tap,
)

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


def _enter_pressed() -> bool:
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
    protocol = "type2" if args.to.startswith("tcp://") else "auto"
    header: Mapping[str, object] = {}
    target: ReplayTarget
    if is_tap(args.to):
        spec = args.to.removeprefix("tap://").removeprefix("tap:")
        tap_target = TapTarget(spec, send_dir)
        header = tap_target.header
        target, out_dir, reply_dir = tap_target, tap_target.send_dir, tap_target.reply_dir
    else:
        out_dir, reply_dir = send_dir, reverse_direction(send_dir)
        target = StreamTarget(args.to, capture_profile(capture, args.profile, None, protocol),
                              reply_dir, args.baud or 9600)  # fmt: skip
    try:
        named = str(header["profile"]) if header.get("profile") else None
        profile = capture_profile(capture, args.profile, named, protocol)
        printer = FramePrinter(
            profile, chart=load_chart(args.chart) if args.chart else None,
            colour=args.colour, as_json=args.json,
        )  # fmt: skip
        writers = [open_writer(p, link=profile.protocol, profile=profile.name) for p in args.record]

        def shown(note: str) -> Callable[[CaptureRecord], None]:
            def show(rec: CaptureRecord) -> None:
                for w in writers:
                    w.write(rec)
                if not args.quiet:
                    printer.show(rec, note)

            return show

        replay = Replay(
            target, to_send, out_dir, timing=args.timing, max_gap=args.max_gap,
            pace=args.baud or (None if args.to.startswith("tcp://") or header else 9600),
            wait=args.wait, on_sent=shown("  (sent)"), on_reply=shown("  (reply)"),
            step_go=_enter_pressed if sys.stdin.isatty() else None, name=args.to,
        )  # fmt: skip
        replies = replay.run()
        for w in writers:
            w.close()
    finally:
        target.close()
    if not args.quiet and not args.json:
        print(
            f"replay: {len(to_send)} frames sent ({out_dir}), {len(replies)} replies ({reply_dir})"
        )
    if expect is not None:
        got, diff = compare(expect, (send_dir, out_dir), replies, profile)
        if diff is not None:
            print(f"replay: replies differ from {args.expect}: {diff}", file=sys.stderr)
            return 1
        if not args.json:
            print(f"replay: the {got} replies match {args.expect}")
    return 0
