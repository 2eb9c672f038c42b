"""`ktcs-bench encode`: build one frame from the command line -- the inverse of `decode`."""

from __future__ import annotations

import argparse
import json

from ktcs_bench.codec.frame import FrameCodec
from ktcs_bench.codec.hextext import hex_bytes
from ktcs_bench.codec.opcodes import Opcode
from ktcs_bench.codec.profile import get_profile
from ktcs_bench.codec.render import bracketed, to_json
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import UsageError

EPILOG = """\
payload: give --data HEX (raw DATA bytes), or build it from the opcode's layout in the profile:
  --field NAME=VALUE (repeatable, fixed fields), --items CODE=STATE,... (CHANGE, INDICATION,
  CONTROL), --statuses S,S,... (ALL_INFO).

examples:
  ktcs-bench encode --seq 0x10 --op REQUEST_ALL --field start=0 --field count=0xFFFF
  ktcs-bench encode --seq 5 --op CHANGE --items 3=1,260=0
  ktcs-bench encode --protocol type2 --seq 0 --op IDENT --sub 0 --field station=20 --field version=1
  ktcs-bench encode --profile ktcs-type1-fig7 --seq 0x10 --op 0 --data '00 84' --format brackets
"""

FORMATS = ("hex", "compact", "brackets", "angle", "json")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "encode",
        help="build a frame from fields (the inverse of decode)",
        description="Build one Type I / Type II frame from its fields, using the YAML profile.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--protocol", choices=("type1", "type2"), default="type1")
    p.add_argument("--profile", help="profile name or FILE.yaml[:NAME] (default: the protocol's)")
    p.add_argument("--seq", required=True, type=lambda s: int(s, 0), help="sequence number")
    p.add_argument("--op", required=True, help="opcode name (CHANGE) or number (0x0002)")
    p.add_argument("--sub", type=lambda s: int(s, 0), help="SUB_OP_CODE (type2; default 0)")
    p.add_argument("--data", help="raw DATA bytes as hex")
    p.add_argument("--field", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--items", metavar="CODE=STATE,...", help="items for CHANGE/INDICATION/CONTROL")
    p.add_argument("--statuses", metavar="S,S,...", help="status bytes for ALL_INFO")
    p.add_argument("--format", choices=FORMATS, default="hex", help="output form (default: hex)")
    p.set_defaults(handler=run)


def _int(text: str, what: str) -> int:
    try:
        return int(text.strip(), 0)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number") from None


def build_data(opcode: Opcode | None, args: argparse.Namespace) -> bytes:
    if args.data is not None:
        if args.field or args.items or args.statuses:
            raise UsageError("give --data or --field/--items/--statuses, not both")
        raw = hex_bytes(args.data)
        if raw is None:
            raise UsageError(f"--data: {args.data!r} is not hex")
        return raw
    values: dict[str, int | list[int] | list[list[int]]] = {}  # fields, "items", "statuses"
    for f in args.field:
        name, sep, value = f.partition("=")
        if not sep:
            raise UsageError(f"--field {f!r}: expected NAME=VALUE")
        values[name.strip()] = _int(value, f"--field {name}")
    if args.items:
        pairs = [p.partition("=") for p in args.items.split(",") if p.strip()]
        if any(not sep for _, sep, _ in pairs):
            raise UsageError("--items: expected CODE=STATE,CODE=STATE")
        values["items"] = [[_int(c, "--items"), _int(s, "--items")] for c, _, s in pairs]
    if args.statuses:
        values["statuses"] = [_int(s, "--statuses") for s in args.statuses.split(",") if s.strip()]
    if opcode is None:
        if values:
            raise UsageError("unknown opcode number: give its DATA with --data")
        return b""
    return opcode.build(values)


def run(args: argparse.Namespace) -> int:
    profile = get_profile(args.profile or args.protocol)
    found = profile.opcodes.lookup(args.op)
    opcode = found if isinstance(found, Opcode) else None
    op = found.op if isinstance(found, Opcode) else found
    if args.sub is not None and not profile.has_sub:
        raise UsageError(f"profile {profile.name} has no SUB field")
    sub = (args.sub or 0) if profile.has_sub else None
    frame = FrameCodec(profile).encode(args.seq, op, build_data(opcode, args), sub)
    if args.format == "json":
        dec = StreamDecoder(profile)
        (record,) = dec.feed(frame) + dec.close()
        print(json.dumps({**to_json(record, profile), "hex": frame.hex()}, ensure_ascii=False))
    elif args.format == "compact":
        print(frame.hex().upper())
    elif args.format == "brackets":
        print(bracketed(frame, per_line=len(frame)))
    elif args.format == "angle":
        print(bracketed(frame, "<>", per_line=len(frame)))
    else:
        print(frame.hex(" ").upper())
    return 0
