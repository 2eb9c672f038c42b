"""`ktcs-bench emulator KIND`: run one device alone, as its own process, so a real device can take
another's place (SPEC §7)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from ktcs_bench.emulator import build
from ktcs_bench.lab.topology import load_lab, resolve_lab_path
from ktcs_bench.transport.endpoints import parse_endpoint

DESCRIPTION = """\
Run one emulated device as its own process. It prints one JSON line when it is ready (its control
port, the pty paths it made, the address it listens on) and logs to stderr.

ENDPOINT forms (--link PEER=ENDPOINT; PEER is a role: ctc, ixl, atc, io (the trackside: `trackside`
too), rails, or a device name from the lab file):
  /dev/ttyUSB0, loop://, socket://H:P, rfc2217://H:P   a serial device or any pyserial URL (Type I)
  pty                                                  make a pty pair here, print the path
  tcp://HOST:PORT                                      connect (Type II to the CTC, the rails)
"""
EPILOG = """\
examples:
  # an ATC for station 18 on a pty, waiting for a real IXL on the path it prints
  ktcs-bench emulator atc --station 18 --link ixl=pty
  # our IXL for station 20 against a real CTC and real trackside I/O on a USB RS485 adapter
  ktcs-bench emulator ixl --station 20 --link ctc=tcp://10.0.0.1:5000 --link io=/dev/ttyUSB0
  # the CTC alone, Type II on all interfaces, port 5000
  ktcs-bench emulator ctc --listen 0.0.0.0:5000
"""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "emulator", help="run one emulated device (ctc, ixl, atc, trackside, trackcircuit, train)",
        description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    build.arguments(p)
    p.set_defaults(handler=run)


def build_device(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The device of the command line, in the lab file it names."""
    return build.build_device(args, load_lab(resolve_lab_path(args.lab)))


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )  # fmt: skip
    device = build_device(args)
    device.lifeline, device.token_file = args.lifeline, args.token_file
    code: int = asyncio.run(device.run())
    return code


__all__ = ["parse_endpoint", "register"]
