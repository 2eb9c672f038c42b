"""`ktcs-bench dissector`: write the Wireshark dissector (Lua) generated from the wire profiles."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.codec.profile import FrameProfile, get_profile, load_profiles, shipped_profiles
from ktcs_bench.dissector import PLUGIN_NAME, generate, personal_lua_plugins
from ktcs_bench.errors import UsageError

HELP = "write a Wireshark dissector (Lua) for ktcs1/ktcs2, generated from the wire profiles"
DESCRIPTION = """\
Write one self-contained Lua dissector generated from every shipped wire profile
(protocols/*.yaml) and any --profile of your own: protocol ktcs1 (Type I; LINKTYPE_USER0 captures
open with no preference changed) and ktcs2 (Type II over TCP: heuristic, Decode As, TCP ports).
Fields, opcode and sub-opcode names, payload layouts, CRC, STX/ETX and length limits all come
from the profiles. In Wireshark the preferences ktcs1.profile / ktcs2.profile pick the profile
(default: the bench's).
"""
EPILOG = """\
examples:
  ktcs-bench dissector --out ktcs.lua
  tshark -2 -X lua_script:ktcs.lua -r st18.pcapng -V
  tshark -2 -X lua_script:ktcs.lua -o ktcs1.profile:ktcs-type1-fig7 -r fig7.pcapng
  tshark -2 -X lua_script:ktcs.lua -d tcp.port==5020,ktcs2 -r st20-ctc.pcapng
  ktcs-bench dissector --install --profile vendor.yaml:acme-t1 --chart code_charts/st18_ixl_to_atc.yaml

exit status: 0 written; 2 bad arguments, profile or chart, or the file cannot be written.
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "dissector",
        help=HELP,
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", metavar="FILE", help="write the dissector here ('-' for stdout)")
    p.add_argument(
        "--install", action="store_true",
        help=f"write it as {PLUGIN_NAME} in Wireshark's personal Lua plugin folder "
        "(`tshark -G folders`), where Wireshark and tshark load it by themselves",
    )  # fmt: skip
    p.add_argument(
        "--profile", action="append", default=[], metavar="FILE.yaml[:NAME]",
        help="a profile of your own besides the shipped ones (repeatable; FILE.yaml alone: all "
        "of its profiles)",
    )  # fmt: skip
    p.add_argument("--chart", help="code chart YAML: code names for items and statuses")
    p.set_defaults(handler=run)


def _profiles(extra: list[str]) -> list[FrameProfile]:
    chosen = dict(shipped_profiles())
    for spec in extra:
        path, _, name = (
            spec.partition(":") if ".yaml:" in spec or ".yml:" in spec else (spec, "", "")
        )
        if not path.endswith((".yaml", ".yml")):
            raise UsageError(f"--profile wants FILE.yaml[:NAME], not {spec!r}")
        found = [get_profile(spec)] if name else list(load_profiles(path).values())
        for prof in found:
            known = chosen.get(prof.name)
            if known is not None and Path(known.source).resolve() != Path(prof.source).resolve():
                raise UsageError(f"profile {prof.name} of {prof.source} is also in {known.source}")
            chosen[prof.name] = prof
    return list(chosen.values())


def _write(path: Path, text: str) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


def run(args: argparse.Namespace) -> int:
    if not args.out and not args.install:
        raise UsageError("say where: --out FILE, --out - (stdout) or --install")
    profiles = _profiles(args.profile)
    chart = load_chart(args.chart) if args.chart else None
    text = generate(profiles, chart)
    targets: list[Path] = []
    if args.out == "-":
        sys.stdout.write(text)
    elif args.out:
        targets.append(Path(args.out))
    if args.install:
        targets.append(personal_lua_plugins() / PLUGIN_NAME)
    for path in targets:
        _write(path, text)
    report = sys.stderr if args.out == "-" else sys.stdout
    by_protocol = {
        short: ", ".join(p.name for p in profiles if p.protocol == protocol)
        for short, protocol in (("ktcs1", "type1"), ("ktcs2", "type2"))
    }
    listing = "; ".join(f"{short}: {names}" for short, names in by_protocol.items())
    for path in targets:
        print(f"wrote {path} ({listing})", file=report)
    if args.out and args.out != "-":
        print(f"use: tshark -2 -X lua_script:{args.out} -r CAPTURE.pcapng -V", file=report)
    return 0
