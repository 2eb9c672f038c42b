"""`ktcs-bench threats`: the seven EN 50159 threats injected through the taps of running links,
each reported with the defence that caught it and the application outcome."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from ktcs_bench.cli._common import positive
from ktcs_bench.errors import UsageError

if TYPE_CHECKING:
    from ktcs_bench.threats.report import ThreatResultJson


class TargetJson(TypedDict):
    """A tapped link of the campaign in its JSON report: who received the frames, from where the
    application was read, the timings judged by."""

    tap: str
    protocol: str
    dut: str
    peer: str
    application: str | None
    timing: dict[str, float | int | None]


class CampaignJson(TypedDict):
    """`threats --json`: the targets and each threat's result."""

    targets: list[TargetJson]
    results: list[ThreatResultJson]


HELP = "inject the EN 50159 threats into running links through their taps; report the defences"
DESCRIPTION = """\
Inject repetition, deletion, insertion, resequencing, corruption, delay and masquerade through the
taps of running links, one after the other, and report for each the defence that caught it (SEQ,
CRC, timeout, IDENT/admission) and what the application did (nothing acted on from a corrupted or
masqueraded frame; fail-safe on loss).

  --target TAP    a running link's tap: its name (`lab up` names taps after links, `tap run
                  --name`) or its control address HOST:PORT. A Type I tap gets repetition,
                  deletion, insertion and corruption, aimed at its device under test (--dut);
                  a Type II tap gets resequencing, delay and masquerade, aimed at the CTC.
                  Give one of each for all seven.
  (no --target)   start a small lab of our emulators (CTC, one station's IXL and ATC, track
                  circuits) with a tap in each link, and attack that.

The application outcome is read from the devices when they are ours: the running lab that owns the
tap (found from the tap's name, or --lab), or the small lab. A real device cannot be read; its
outcome is reported as "not observed" next to what the wire showed.
"""
EPILOG = """\
examples:
  ktcs-bench threats                                  # the small lab, all seven threats
  ktcs-bench lab up &                                 # then, against the reference lab:
  ktcs-bench threats --target st18-atc --target st18-ctc --markdown threats.md --junit threats.xml
  ktcs-bench threats --target 127.0.0.1:40111 --dut ixl --threat corruption --json

exit codes: 0 every threat run was caught and no outcome was unsafe, 1 a threat was missed or an
outcome unsafe, 2 usage error, 3 a tap or device could not be reached.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("threats", help=HELP, description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--target", action="append", default=[], metavar="TAP",
                   help="a running link's tap (name or HOST:PORT); repeatable")  # fmt: skip
    p.add_argument("--dut", metavar="END",
                   help="Type I: the tap end under test (default: the tap's first end, the IXL "
                        "in a lab)")  # fmt: skip
    p.add_argument("--lab", metavar="LAB",
                   help="with --target: the running lab whose devices to read (default: the lab "
                        "that owns the tap); without: the lab file for the small lab's line data")  # fmt: skip
    p.add_argument("--station", type=positive(int),
                   help="the small lab's station (default 18); with --target: the station the "
                        "Type II link carries, if its IDENT is not on the tap's record")  # fmt: skip
    p.add_argument("--threat", action="append", default=[], help="run only these threats")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--markdown", metavar="FILE", help="also write the Markdown table here")
    p.add_argument("--junit", metavar="FILE", help="also write a JUnit XML report (a CI reads it)")
    p.set_defaults(handler=run)


def _lab_name(lab: str | None) -> str | None:
    if lab is None:
        return None
    from ktcs_bench.lab.topology import load_lab, resolve_lab_path

    path = resolve_lab_path(lab)
    return load_lab(path).name if path.is_file() else lab


def run(args: argparse.Namespace) -> int:
    from ktcs_bench.threats import (
        THREATS,
        Application,
        ThreatTarget,
        WireTap,
        find_in_labs,
        run_campaign,
    )
    from ktcs_bench.threats.minilab import ThreatLab
    from ktcs_bench.threats.report import junit_xml, markdown, summary

    unknown = [t for t in args.threat if t not in THREATS]
    if unknown:
        raise UsageError(f"unknown threat(s) {', '.join(unknown)} (known: {', '.join(THREATS)})")
    colour: bool = args.colour

    def progress(text: str) -> None:
        if not args.json and sys.stderr.isatty():
            print(f"  {text}", file=sys.stderr, flush=True)

    with contextlib.ExitStack() as stack:
        if args.target:
            targets = []
            lab_name = _lab_name(args.lab)
            for spec in args.target:
                wire = stack.enter_context(WireTap(spec))
                # Type II: the CTC, the tap's target end; Type I: --dut, else the first end
                dut = wire.names[1] if wire.protocol == "type2" else args.dut or wire.names[0]
                app = find_in_labs(wire.name, lab_name)
                if wire.protocol == "type1" and app.readable and app.device != dut:
                    app = Application()  # the bench reads IXLs: a Type I DUT that is not one
                targets.append(ThreatTarget(wire, dut, app, station=args.station))
            chosen = args.threat or None
            protocols = {t.tap.protocol for t in targets}
            missing = [n for n in chosen or [] if THREATS[n][0] not in protocols]
            if missing:
                raise UsageError(f"{', '.join(missing)}: no target of that link type")
        else:
            lab = stack.enter_context(ThreatLab(args.station or 18, args.lab))
            targets = lab.targets()
            chosen = args.threat or None
        results = run_campaign(targets, chosen, progress=progress)
    header = [f"ktcs-bench threats: {len(targets)} target(s)"]
    for t in targets:
        tm = t.timing
        timing = (f"T_MAX {tm.t_max:g} s, link-test period {tm.link_test_period:g} s, ACK timeout "
                  f"{tm.ack_timeout * 1000:.0f} ms, retry count {tm.retry_count}"
                  if t.tap.protocol == "type1" else f"T_MAX {tm.t2_t_max:g} s, heartbeat period "
                  f"{tm.heartbeat_period:g} s, retry count {tm.retry_count}")  # fmt: skip
        header.append(f"  {t.link}: {timing}; application read from "
                      f"{t.app.source or 'nowhere (not our emulators)'}")  # fmt: skip
    properties = {f"target.{t.tap.name}": f"{t.link}; application: {t.app.source or 'not read'}"
                  for t in targets}  # fmt: skip
    for path, data in ((args.markdown, (markdown(results) + "\n").encode()),
                       (args.junit, junit_xml(results, properties))):  # fmt: skip
        if path:
            try:
                Path(path).write_bytes(data)
            except OSError as exc:
                raise UsageError(f"cannot write {path}: {exc.strerror}") from None
    if args.json:
        report: CampaignJson = {
            "targets": [
                {
                    "tap": t.tap.name,
                    "protocol": t.tap.protocol,
                    "dut": t.dut,
                    "peer": t.peer,
                    "application": t.app.source or None,
                    "timing": t.timing.describe(),
                }
                for t in targets
            ],  # fmt: skip
            "results": [r.as_dict() for r in results],
        }
        print(json.dumps(report, ensure_ascii=False, indent=2))
    else:
        print(summary(results, header, colour))
    sys.stdout.flush()
    return 0 if all(r.passed for r in results) else 1
