"""Entry point of the `ktcs-bench` command; discovers subcommands in `ktcs_bench.cli`."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import signal
import sys
import threading
from collections.abc import Sequence

from ktcs_bench import __version__
from ktcs_bench.cli._common import use_colour
from ktcs_bench.errors import ConfigError, KtcsError, PeerError, UsageError

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_USAGE = 2
EXIT_PEER = 3
EXIT_INTERRUPTED = 130

DESCRIPTION = """\
ktcs-bench: a kTCS signalling laboratory in a box.

Run an emulated CTC, interlockings, wayside ATC, trackside I/O, track circuits and trains, linked
by the real Type I (serial) and Type II (TCP) protocols; decode, monitor, replay and fault-inject
any link; check a device against the protocol conformance suite.
"""

EPILOG = """\
examples:
  ktcs-bench lab up                                  # the reference lab: 3 stations, CTC, ATC, I/O
  ktcs-bench ctc route set 18 S1 S11                 # operate it from another shell
  ktcs-bench monitor st18-atc                        # watch a link decoded live, Fig. 7 style
  ktcs-bench decode protocols/captures/fig7.hex --profile auto
  ktcs-bench emulator atc --station 18 --link ixl=pty   # one device alone, for a real peer
  ktcs-bench conformance --role atc --target /dev/ttyUSB0
  ktcs-bench scenario run emulators/scenarios/seed001_follower.yaml
  ktcs-bench test run emulators/procedures/*.yaml --junit junit.xml --report out/
  ktcs-bench trace junit.xml out/ --out trace/        # requirements -> checks -> verdicts
  ktcs-bench dissector --install                     # Wireshark shows ktcs1/ktcs2 in captures

colour: on a terminal, unless NO_COLOR is set; --colour / --no-colour (any command) decide.

exit codes: 0 ok, 1 a check failed (bad CRC, failed case), 2 usage/config error,
            3 peer or I/O failure, 130 interrupted (143: stopped by SIGTERM).
"""


def _add_colour_option(parser: argparse.ArgumentParser, top: bool) -> None:
    """`--colour/--no-colour` (and, unlisted, `--color/--no-color`) on `parser` and every
    subcommand under it. Below the top an option given overrides; unset, it leaves the top's value."""
    parser.add_argument(
        "--colour", dest="colour", action=argparse.BooleanOptionalAction,
        default=None if top else argparse.SUPPRESS,
        help="colour the output or not (default: on a terminal, unless NO_COLOR is set)",
    )  # fmt: skip
    parser.add_argument("--color", dest="colour", action=argparse.BooleanOptionalAction,
                        default=argparse.SUPPRESS, help=argparse.SUPPRESS)  # fmt: skip
    seen: set[int] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                if id(child) not in seen:  # aliases name the same parser
                    seen.add(id(child))
                    _add_colour_option(child, top=False)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; with `command` (the word after `ktcs-bench`), of that one
    alone when it is a module here that registers it. A lab starts dozens of `ktcs-bench emulator`
    processes: each then imports what a device needs, not every command's modules."""
    if command is not None and not command.startswith("_") and command != "main":
        parser = _parser([command])
        if command in _commands(parser):
            return parser
    return _parser(None)


def _commands(parser: argparse.ArgumentParser) -> set[str]:
    return {
        name
        for action in parser._actions
        if isinstance(action, argparse._SubParsersAction)
        for name in action.choices
    }


def _parser(only: list[str] | None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ktcs-bench",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"ktcs-bench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    import ktcs_bench.cli as cli_pkg

    for info in sorted(pkgutil.iter_modules(cli_pkg.__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.name == "main":
            continue
        if only is not None and info.name not in only:
            continue
        module = importlib.import_module(f"ktcs_bench.cli.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    _add_colour_option(parser, top=True)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    # the top-level options take no value: the first other word names the command
    parser = build_parser(next((w for w in words if not w.startswith("-")), None))
    args = parser.parse_args(words)
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return EXIT_USAGE
    args.colour = use_colour(sys.stdout, args.colour)  # decided once, for every command
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C is KeyboardInterrupt (exit 130) even when started as a shell's background job,
        # which inherits SIGINT ignored: the commands with their own handlers react to it anyway
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return int(handler(args))
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return EXIT_OK
    except (ConfigError, UsageError) as exc:
        print(f"ktcs-bench: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except PeerError as exc:
        print(f"ktcs-bench: peer error: {exc}", file=sys.stderr)
        return EXIT_PEER
    except KtcsError as exc:
        print(f"ktcs-bench: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
