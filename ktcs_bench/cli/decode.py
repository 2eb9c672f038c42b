"""`ktcs-bench decode`: hex text in any common form -> frames with every field and the CRC verdict."""

from __future__ import annotations

import argparse

from ktcs_bench.charts.model import CodeChart, load_chart
from ktcs_bench.cli._common import print_json_line, read_text_inputs
from ktcs_bench.codec.frame import Frame, Record
from ktcs_bench.codec.hextext import HexText, parse_hex_text
from ktcs_bench.codec.profile import FrameProfile, get_profile, profile_names
from ktcs_bench.codec.render import BOLD, RESET, to_json, to_text
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import UsageError

HELP = "decode hex frames (console captures, hex dumps, hex logs) into fields and CRC verdicts"
DESCRIPTION = """\
Decode Type I / Type II frames from hex text. The input is hex in any common form, mixed freely:
  <02><04><00>...      [02][84][00]...      02 04 00 ...      020400...      0x02,0x04,...
  xxd / hexdump -C dumps, the seed 004 Fig. 7 console lines ("수신 = <02>...", "송신 = [02]...",
  wrapped over several lines), and the bench's hex logs ("<seconds> <direction> <hex>").
Lines that are not hex (console annotations) are skipped. The bytes are decoded as one stream,
so a frame may span lines and garbage between frames is reported with its offset.
"""
EPILOG = """\
examples:
  ktcs-bench decode protocols/captures/fig7.hex --profile auto
  ktcs-bench decode '02 00 00 10 06 00 03 87 00 00 03'
  ktcs-bench decode --protocol type2 --json '02 03 01 30 00 3C 44'
  xxd capture.bin | ktcs-bench decode --chart code_charts/st20_ixl_to_ctc.yaml

exit status: 0 every frame checks; 1 a frame failed a check (crc, etx, length, truncated, format)
or no frame was found; 2 bad arguments, profile or chart.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "decode",
        help=HELP,
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="*", metavar="HEX|FILE", help="hex text or a file; '-' stdin")
    p.add_argument(
        "--protocol", choices=("type1", "type2", "auto"), default="auto",
        help="which protocol's profiles to try (default: auto, all of them)",
    )  # fmt: skip
    p.add_argument(
        "--profile", default="auto",
        help="profile name (ktcs-type1, ktcs-type1-fig7, ktcs-type2), FILE.yaml[:NAME] of your own, "
        "or auto: try each and take the one whose CRC checks (default)",
    )  # fmt: skip
    p.add_argument("--chart", help="code chart YAML: show code names for items and statuses")
    p.add_argument("--json", action="store_true", help="one JSON object per frame (SPEC §7 keys)")
    p.set_defaults(handler=run)


def decode_all(data: bytes, profile: FrameProfile) -> list[Record]:
    dec = StreamDecoder(profile)
    return dec.feed(data) + dec.close()


def choose_profile(data: bytes, protocol: str) -> tuple[FrameProfile, list[Record], dict[str, int]]:
    """Try each shipped profile; the one with the most CRC-good frames wins (ties: listed first)."""
    names = profile_names(None if protocol == "auto" else protocol)
    scores: dict[str, int] = {}
    best: tuple[int, int, FrameProfile, list[Record]] | None = None
    for rank, name in enumerate(names):
        prof = get_profile(name)
        records = decode_all(data, prof)
        good = sum(1 for r in records if isinstance(r, Frame) and r.error is None)
        scores[name] = good
        if best is None or good > best[0]:
            best = (good, rank, prof, records)
    if best is None:
        raise UsageError(f"no shipped profile for protocol {protocol}")
    return best[2], best[3], scores


def run(args: argparse.Namespace) -> int:
    text = read_text_inputs(args.inputs)
    hex_text: HexText = parse_hex_text(text)
    data = hex_text.data
    if not data:
        raise UsageError("no hex bytes found in the input")
    chart: CodeChart | None = load_chart(args.chart) if args.chart else None
    colour: bool = args.colour
    if args.profile == "auto":
        profile, records, scores = choose_profile(data, args.protocol)
        if not args.json:
            tried = ", ".join(f"{n}: {s}" for n, s in scores.items())
            verdict = "CRC checks" if scores[profile.name] else "no profile's CRC checks; showing"
            print(f"profile auto: {verdict} {profile.name}  (good frames per profile: {tried})")
    else:
        profile = get_profile(args.profile)
        if args.protocol != "auto" and profile.protocol != args.protocol:
            raise UsageError(f"profile {profile.name} is {profile.protocol}, not {args.protocol}")
        records = decode_all(data, profile)
    failed = not any(isinstance(r, Frame) for r in records)
    for record in records:
        if isinstance(record, Frame) and record.error is not None:
            failed = True
        if args.json:
            obj = to_json(record, profile)
            failed = failed or bool(obj.get("error"))
            print_json_line(obj)
            continue
        origin = hex_text.origin(record.offset)
        label = ""
        if origin is not None:
            parts = [f"line {origin.line}"]
            if origin.direction:
                parts.insert(0, origin.direction)
            if origin.time is not None:
                parts.insert(0, f"t={origin.time:.6f}")
            label = " ".join(parts) + "  "
        print(to_text(record, profile, chart, colour, label))
        print()
    if not args.json:
        frames = [r for r in records if isinstance(r, Frame)]
        good = sum(1 for f in frames if f.error is None)
        summary = f"{len(frames)} frames, {good} good, {len(frames) - good} with errors"
        garbage = sum(len(r.raw) for r in records if not isinstance(r, Frame))
        if garbage:
            summary += f", {garbage} garbage bytes"
        if hex_text.skipped_lines:
            summary += f"; {len(hex_text.skipped_lines)} non-hex lines skipped"
        print(f"{BOLD}{summary}{RESET}" if colour else summary)
    return 1 if failed else 0
