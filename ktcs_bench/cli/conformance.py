"""`ktcs-bench conformance`: the protocol conformance suite against any endpoint (SPEC §7)."""

from __future__ import annotations

import argparse
import ssl
import sys
from pathlib import Path

from ktcs_bench import kinds
from ktcs_bench.cli._common import duration, positive
from ktcs_bench.errors import UsageError

HELP = "run the protocol conformance suite against a device (ours or a real one)"
DESCRIPTION = """\
Run named conformance cases against a device and give each a verdict (pass/fail/error/skip) with
its evidence: every frame exchanged, both directions, timestamped. The suite is built from raw
frames, so it judges the device, not the bench's own link code.

  --role atc|trackside --target SERIAL     the suite plays the IXL on the device's Type I line
  --role ixl --target SERIAL [--peer io]   the suite plays the ATC (or trackside I/O)
  --role ixl --target SERIAL --peer east   the suite plays the neighbouring IXL on the IXL's
                                           interval link (east or west, SPEC §6.6)
  --role ixl --target listen://HOST:PORT   the suite plays the CTC; point the IXL at HOST:PORT
  --role ctc --target tcp://HOST:PORT      the suite plays an IXL client of the CTC

SERIAL: a device path (/dev/ttyUSB0), a pty path, or any pyserial URL (rfc2217://h:p, socket://h:p).
Timings default to SPEC §3.4/§4 for the profile and the line; name them as a signalling engineer
does: --delta-r, --ack-timeout, --heartbeat-period (Type I link-test period), --t-max, --retry-count.
Every report gives the device's timers as measured on the wire; --timings auto measures them first
(a device whose documentation is missing) and judges the device by them.
A device that sends not one byte in a case stops the run: "no device answered", exit 3.
"""
EPILOG = """\
examples:
  ktcs-bench emulator atc --station 18 --link ixl=pty        # prints {"ptys": {"ixl": "/dev/pts/7"}}
  ktcs-bench conformance --role atc --target /dev/pts/7 --station 18 --junit atc.xml
  ktcs-bench conformance --role ixl --target listen://127.0.0.1:6100 --station 18 &
  ktcs-bench emulator ixl --station 18 --link ctc=tcp://127.0.0.1:6100
  ktcs-bench conformance --role ctc --target tcp://127.0.0.1:5000 --station 20 --case t2-seq-gap

  ktcs-bench conformance --role atc --target /dev/ttyUSB0 --timings auto --json

exit codes: 0 every case passed, 1 a case failed, 2 usage/config, 3 peer or I/O failure (among
them: no device answered, or a case was inconclusive because the suite broke its premise).
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("conformance", help=HELP, description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument(
        "--role",
        choices=kinds.CONFORMANCE_KINDS,
        help="the device under test",
    )
    p.add_argument("--target", help="the device's endpoint (see above)")
    p.add_argument("--ics", metavar="FILE",
                   help="the device's conformance statement (YAML: role, optional opcodes, link "
                   "test, largest frame, timings): the cases it rules out are reported not "
                   "applicable; its role and timings are the defaults (emulators/ics/)")  # fmt: skip
    p.add_argument("--profile", help="framing profile (default ktcs-type1 / ktcs-type2; type2-tls "
                   "= ktcs-type2 inside TLS, needs --tls-cert/--tls-key/--tls-ca)")  # fmt: skip
    p.add_argument("--case", action="append", default=[], metavar="NAME", help="run only these")
    p.add_argument("--junit", metavar="FILE", help="write a JUnit XML report here")
    p.add_argument("--json", action="store_true", help="print the results as JSON (with frames)")
    p.add_argument(
        "--station", type=positive(int), help="station number (sizes the chart; ctc: our IDENT)"
    )
    p.add_argument("--peer", choices=(*kinds.TYPE1_ROLES, *kinds.NEIGHBOUR_ROLES),
                   default=kinds.ATC,
                   type=lambda word: kinds.link_role(word) or word,  # trackside: its role, io
                   help="--role ixl on a serial line: which of its links this is (atc, io, or "
                   "west/east: its interval link to a neighbouring IXL, the suite playing that "
                   "IXL)")  # fmt: skip
    p.add_argument("--codes", type=positive(int), help="codes in the device's transmit chart (else from "
                   "--station and the lab's charts)")  # fmt: skip
    p.add_argument("--lab", help="lab file for the charts (default: the reference lab)")
    g = p.add_argument_group("timing (defaults: SPEC §3.4 / §4)")
    g.add_argument("--timings", choices=("given", "auto"), default="given",
                   help="given: judge by the figures below (default); auto: measure the device's "
                   "timers first and judge by what was measured")  # fmt: skip
    g.add_argument(
        "--line-rate", type=positive(float), default=9600.0, help="bit/s of the device's line"
    )
    g.add_argument("--unpaced", action="store_true", help="the device does not pace its line "
                   "(an emulator run with --unpaced): wire times count as 0")  # fmt: skip
    g.add_argument(
        "--longest-frame", type=positive(int), help="DATA bytes of the longest frame (sizes ΔR)"
    )
    g.add_argument("--delta-r", type=duration, metavar="S", help="ΔR, the frame timeout")
    g.add_argument("--ack-timeout", type=duration, metavar="S", help="the ACK timeout")
    g.add_argument("--heartbeat-period", "--link-test-period", type=duration, metavar="S",
                   help="Type II heartbeat / Type I link-test period (1 s)")  # fmt: skip
    g.add_argument(
        "--t-max", type=duration, metavar="S", help="T_MAX: silence before the link is down"
    )
    g.add_argument(
        "--retry-count",
        type=positive(int, 0),
        help="retransmissions before communication error (3)",
    )
    g.add_argument("--tolerance", type=duration, default=0.75, metavar="S",
                   help="how late a timer may fire and still pass (default 0.75 s)")  # fmt: skip
    t = p.add_argument_group("TLS (Type II, profile type2-tls)")
    t.add_argument("--tls-cert", help="the suite's certificate (PEM)")
    t.add_argument("--tls-key", help="the suite's private key (PEM)")
    t.add_argument("--tls-ca", help="CA the device's certificate must chain to")
    t.add_argument("--tls-server-name", help="--role ctc: the name in the CTC's certificate")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.add_argument("--list-faults", action="store_true", help="list the emulator fault variants")
    p.add_argument("-v", "--verbose", action="store_true", help="show every check of every case")
    p.set_defaults(handler=run)


def _tls(args: argparse.Namespace, server: bool) -> ssl.SSLContext | None:
    if not (args.tls_cert or args.tls_key or args.tls_ca):
        if args.profile == "type2-tls":
            raise UsageError("profile type2-tls needs --tls-cert, --tls-key and --tls-ca")
        return None
    purpose = ssl.Purpose.CLIENT_AUTH if server else ssl.Purpose.SERVER_AUTH
    try:
        ctx = ssl.create_default_context(purpose, cafile=args.tls_ca)
        if args.tls_cert:
            ctx.load_cert_chain(args.tls_cert, args.tls_key)
    except (OSError, ssl.SSLError) as exc:
        raise UsageError(f"TLS: {exc}") from None
    if server and args.tls_ca:
        ctx.verify_mode = ssl.CERT_REQUIRED
    return ctx


def _codes(args: argparse.Namespace, protocol: str) -> int | None:
    if args.codes is not None:
        return int(args.codes)
    if args.station is None:
        return None
    from ktcs_bench.lab.topology import load_lab, resolve_lab_path
    from ktcs_bench.station_codes.stations import station_chart

    line = load_lab(resolve_lab_path(args.lab)).load_line()
    if args.station not in line.stations:
        raise UsageError(f"station {args.station} is not on the line {sorted(line.stations)}")
    view = line.view(args.station)
    if protocol == "type2":
        chart = "ixl_to_ctc"
    else:
        # a Type I device under test sends its own chart; an IXL, its chart to the suite's peer
        dut = kinds.KINDS[args.role]
        chart = (
            kinds.chart_name(dut.role, outward=False)
            if dut.link == kinds.TYPE1
            else kinds.chart_name(args.peer, outward=True)
        )
    return len(station_chart(view, chart).codes)


def _list() -> None:
    from ktcs_bench.conformance.runner import CASES

    for c in CASES.values():
        print(f"{c.name:28s} {c.protocol}  {c.rule:11s} {c.title}  [{', '.join(c.roles)}]")


def _list_faults() -> None:
    from ktcs_bench.emulator.variants import FAULTS

    for name, v in FAULTS.items():
        print(f"{name:24s} {v.kind:6s} caught by {v.caught_by:28s} {v.breaks}")


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.codec.profile import get_profile
    from ktcs_bench.conformance import report
    from ktcs_bench.conformance.ics import load_ics
    from ktcs_bench.conformance.model import CaseResult
    from ktcs_bench.conformance.runner import SuiteResult, protocol_of, run_suite
    from ktcs_bench.conformance.timing import SuiteTiming
    from ktcs_bench.transport.endpoints import parse_endpoint

    if args.list or args.list_faults:
        _list() if args.list else _list_faults()
        return 0
    ics = load_ics(args.ics) if args.ics else None
    if ics is not None:
        if args.role and args.role != ics.role:
            raise UsageError(f"--role {args.role}: the statement {args.ics} is for role {ics.role}")
        args.role = ics.role
        args.profile = args.profile or ics.profile
        for key in ("delta_r", "ack_timeout", "t_max", "retry_count", "longest_frame"):
            if getattr(args, key) is None:
                setattr(args, key, getattr(ics.timings, key))
        if args.heartbeat_period is None:
            args.heartbeat_period = ics.timings.heartbeat_period or ics.timings.link_test_period
    if not args.role or not args.target:
        raise UsageError("conformance needs --role and --target (or --list)")
    protocol = protocol_of(args.role, parse_endpoint(args.target))
    name = args.profile or ("ktcs-type1" if protocol == "type1" else "ktcs-type2")
    profile = get_profile("ktcs-type2" if name == "type2-tls" else name)
    if ics is not None:
        profile = ics.sized(profile)
    tls = _tls(args, server=args.role == kinds.IXL) if protocol == "type2" else None
    station = args.station
    if station is None and args.role == kinds.CTC:
        from ktcs_bench.lab.topology import load_lab, resolve_lab_path

        station = load_lab(resolve_lab_path(args.lab)).stations[0]
    timing = SuiteTiming.resolve(
        profile, line_rate=None if args.unpaced else args.line_rate,
        longest_frame=args.longest_frame, delta_r=args.delta_r, ack_timeout=args.ack_timeout,
        heartbeat_period=args.heartbeat_period, t_max=args.t_max, retry_count=args.retry_count,
        tolerance=args.tolerance,
    )  # fmt: skip
    colour: bool = args.colour
    live = not args.json
    if live:
        head = SuiteResult(args.role, args.target, protocol, profile.name, timing,
                           auto=args.timings == "auto")  # fmt: skip
        print(report.header(head))
        print(flush=True)

    def progress(suite: SuiteResult, result: CaseResult) -> None:
        if live:
            print(report.case_block(result, colour, args.verbose), flush=True)
            if result.case.name == "measure-timings" and not suite.stopped:
                print(f"      judged from here by: {report.timing_line(suite)}", flush=True)

    suite = run_suite(args.role, args.target, profile, timing, cases=args.case, station=station,
                      codes=_codes(args, protocol), tls=tls, auto=args.timings == "auto",
                      server_hostname=args.tls_server_name, on_result=progress,
                      not_applicable=None if ics is None else ics.not_applicable)  # fmt: skip
    if args.junit:
        try:
            Path(args.junit).write_bytes(report.junit_xml(suite))
        except OSError as exc:
            raise UsageError(f"cannot write {args.junit}: {exc.strerror}") from None
    if args.json:
        print(report.json_text(suite))
    else:
        print("\n" + report.footer(suite, colour))
    if suite.stopped:
        print(f"ktcs-bench: peer error: {suite.stopped}", file=sys.stderr)
        return 3
    if any(r.verdict.value == "fail" for r in suite.results):
        return 1
    if any(r.verdict.value == "error" for r in suite.results):
        return 3
    return 0
