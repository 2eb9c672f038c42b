"""The tap's control language: one command a line, pure parsing (the tap executes, the CLI sends).

    ber RATE [DIR]            bit error rate, e.g. `ber 1e-3` (0 turns it off)
    drop-frame [N] [DIR]      remove the next N whole frames (default 1)
    drop-bytes N [DIR]        remove the next N bytes
    garbage [DIR] HEX...      put these bytes on the wire now, e.g. `garbage a->b 02 ff 00`
    duplicate [N] [DIR]       deliver the next N frames twice
    reorder [DIR]             deliver the next two frames swapped
    delay SECONDS [DIR]       deliver late (0 turns it off)
    cut [DIR]                 cut the link (pty: bytes are lost; TCP: connections are closed and
                              new ones refused); with DIR only that direction loses its bytes
    restore [DIR]             end a cut
    clear                     remove every fault (and end a cut)
    send DIR HEX...           inject bytes as if the sender of DIR had written them (replay)
    token TOKEN               present the tap's token (see below); first, on every connection
    status                    one JSON line: ends, faults, counters
    subscribe [history]       stream the recorded traffic as JSON lines {time, direction, hex},
                              in order with the tap's events {time, event, ...} (fault, send,
                              connected, disconnected)
    help
DIR is `a->b`, `a>b` or `both` (the default), with the tap's end names (`ixl>atc` works too).
The control port obeys a connection only once it has presented the tap's token (its lab's, or the
user's for a tap run on its own; `ktcs-bench` clients find and send it themselves); until then
every line is answered `error refused: ...` and not acted on.
Replies are one line: `ok ...` or `error ...`; `subscribe` replies `ok {...}` then streams.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ktcs_bench.capture.records import split_direction
from ktcs_bench.codec.hextext import hex_bytes
from ktcs_bench.errors import UsageError
from ktcs_bench.faults import (
    BitErrors,
    Cut,
    Delay,
    DropBytes,
    DropFrame,
    DuplicateFrame,
    Fault,
    InsertGarbage,
    ReorderFrames,
)

HELP = __doc__.split("\n\n", 1)[1].split("Replies", 1)[0] if __doc__ else ""
VERBS = ("ber", "drop-frame", "drop-bytes", "garbage", "duplicate", "reorder", "delay", "cut",
         "restore", "clear", "send", "status", "subscribe", "help")  # fmt: skip
_NUMBER = re.compile(r"^[0-9.eE+-]+$")


def token_given(line: str) -> str | None:
    """The token a `token TOKEN` line presents ("" if none follows); None for any other line."""
    words = line.split()
    return (words[1] if len(words) > 1 else "") if words[0].lower() == "token" else None


def refusal(given: str | None) -> str:
    """The reply to a line of a connection not admitted: `given` is the token it presented."""
    why = "no token" if given is None else "wrong token"
    return (
        f"error refused: {why}; this tap obeys only who presents its lab's token first "
        "(`token TOKEN`; see the README, 'Who may operate a lab')"
    )


@dataclass(frozen=True)
class Command:
    verb: str
    direction: str | None = None  # normalised a>b, None = both
    fault: Fault | None = None
    data: bytes = b""
    history: bool = False


def parse_direction(word: str, names: tuple[str, str]) -> str | None:
    """`a->b`/`a>b` with the tap's end names -> "a>b"; `both`/`*` -> None."""
    if word.lower() in ("both", "*", "all"):
        return None
    pair = split_direction(word)
    a, b = names
    if pair is None or set(pair) != {a, b} or pair[0] == pair[1]:
        raise UsageError(f"bad direction {word!r}: use {a}->{b}, {b}->{a} or both")
    return f"{pair[0]}>{pair[1]}"


def _number(word: str, kind: type[float] | type[int], verb: str) -> float:
    try:
        return kind(word)
    except ValueError:
        raise UsageError(f"{verb}: {word!r} is not a number") from None


def parse_command(line: str, names: tuple[str, str] = ("a", "b")) -> Command:
    words = line.split()
    if not words:
        raise UsageError("empty command")
    verb, rest = words[0].lower(), words[1:]
    if verb not in VERBS:
        raise UsageError(f"unknown command {verb!r}; try: {', '.join(VERBS)}")
    direction: str | None = None
    args: list[str] = []
    for w in rest:
        if (">" in w or w.lower() in ("both", "*", "all")) and direction is None:
            direction = parse_direction(w, names)
        else:
            args.append(w)
    if verb == "subscribe":
        return Command(verb, history=bool(args and args[0].lower() == "history"))
    if verb in ("status", "help", "clear", "restore", "cut", "reorder"):
        if args:
            raise UsageError(f"{verb}: unexpected arguments {' '.join(args)}")
        fault: Fault | None = None
        if verb == "cut":
            fault = Cut(direction=direction)
        elif verb == "reorder":
            fault = ReorderFrames(direction=direction)
        return Command(verb, direction, fault)
    if verb in ("garbage", "send"):
        data = hex_bytes(" ".join(args))
        if not data:
            raise UsageError(f"{verb}: give the bytes in hex, e.g. {verb} a->b 02 ff 00")
        if verb == "send":
            if direction is None:
                raise UsageError("send: give the direction, e.g. send a->b 02 00 ...")
            return Command(verb, direction, data=data)
        return Command(verb, direction, InsertGarbage(data, direction=direction))
    # verbs with one number
    if verb in ("ber", "delay", "drop-bytes") and len(args) != 1:
        raise UsageError(f"{verb}: give one number")
    if len(args) > 1 or (args and not _NUMBER.match(args[0])):
        raise UsageError(f"{verb}: unexpected arguments {' '.join(args)}")
    if verb == "ber":
        fault = BitErrors(_number(args[0], float, verb), direction=direction)
    elif verb == "delay":
        fault = Delay(_number(args[0], float, verb), direction=direction)
    elif verb == "drop-bytes":
        fault = DropBytes(int(_number(args[0], int, verb)), direction=direction)
    else:
        n = int(_number(args[0], int, verb)) if args else 1
        if n < 1:
            raise UsageError(f"{verb}: the count must be at least 1")
        cls = DropFrame if verb == "drop-frame" else DuplicateFrame
        fault = cls(n, direction=direction)
    return Command(verb, direction, fault)
