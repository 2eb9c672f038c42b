"""A tap's commands: the words a person types and the JSON its control port takes, pure parsing.

A tap's control port speaks the JSON lines every device's control port speaks (one object a line,
`{"cmd": ...}` in, one answer `{"ok": true, ...}` or `{"ok": false, "error": ...}` back). The words
are for people (`ktcs-bench tap fault st18-atc ber 1e-3`) and are turned into the JSON command on
the client's side. The words:

    ber RATE [DIR]            bit error rate, e.g. `ber 1e-3` (0 turns it off)
    loss RATE [DIR]           each byte lost with this probability (0 turns it off)
    noise RATE [LONGEST] [DIR]  after each byte, with this probability, 1..LONGEST (12) random
                              bytes, half of them starting with a false STX (0 turns it off)
    drop-frame [N] [DIR]      remove the next N whole frames (default 1)
    drop-bytes N [DIR]        remove the next N bytes
    garbage [DIR] HEX...      put these bytes on the wire now, e.g. `garbage a->b 02 ff 00`
    duplicate [N] [DIR]       deliver the next N frames twice
    reorder [DIR]             deliver the next two frames swapped
    corrupt AT [MASK] [DIR]   XOR byte AT of the next frame (negative: from its end) with MASK
                              (default 0x01)
    truncate N [DIR]          the next frame loses its last N bytes
    delay SECONDS [DIR]       deliver late (0 turns it off)
    cut [DIR]                 cut the link (pty: bytes are lost; TCP: connections are closed and
                              new ones refused); with DIR only that direction loses its bytes
    restore [DIR]             end a cut
    clear                     remove every fault (and end a cut)
    send DIR HEX...           inject bytes as if the sender of DIR had written them (replay)
    status                    the tap's ends, faults and counters
    subscribe [history]       stream the recorded traffic as JSON lines {time, direction, hex},
                              in order with the tap's events {time, event, ...} (fault, send,
                              connected, disconnected)
    help
DIR is `a->b`, `a>b` or `both` (the default), with the tap's end names (`ixl>atc` works too).

The JSON: a fault is `{"cmd": VERB, its fields, "direction": "a>b"}` (`{"cmd": "ber", "rate":
0.001}`, `{"cmd": "garbage", "hex": "02ff00"}`: `ktcs_bench.faults`); then `{"cmd": "restore"}`,
`{"cmd": "clear"}`, `{"cmd": "send", "direction": "a>b", "hex": ...}`, `{"cmd": "status"}` (answer
`{"ok": true, "status": {...}}`), `{"cmd": "help"}`, `{"cmd": "subscribe", "history": true}`
(answer `{"ok": true, "profile", "protocol", "names", "tap", "kind"}`, then the stream). A command
that changes the link is answered `{"ok": true, "command": WORDS}`. As every control port, a tap's
obeys a connection only once it has presented the tap's token (its lab's, or the user's for a tap
run on its own): `{"token": TOKEN}` alone (answered `{"ok": true}`) or in any command; until then
each object is answered `{"ok": false, "refused": true, ...}` and not acted on. The bench's clients
find the token and send it themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ktcs_bench.capture.records import split_direction
from ktcs_bench.codec.hextext import hex_bytes
from ktcs_bench.errors import UsageError
from ktcs_bench.faults import FAULTS, Fault, fault_from_json

HELP = __doc__.split("The words:\n\n", 1)[1].split("\nThe JSON", 1)[0] if __doc__ else ""
TAP_VERBS = ("restore", "clear", "send", "status", "subscribe", "help")
VERBS = (*FAULTS, *TAP_VERBS)


def _int(word: str) -> int:
    return int(word, 0)


# the words after a fault's verb, in order: (JSON field, how a word becomes its value, required)
_FAULT_ARGS: dict[str, list[tuple[str, Callable[[str], Any], bool]]] = {
    "ber": [("rate", float, True)],
    "loss": [("rate", float, True)],
    "noise": [("rate", float, True), ("longest", int, False)],
    "drop-frame": [("count", int, False)],
    "drop-bytes": [("count", int, True)],
    "duplicate": [("count", int, False)],
    "reorder": [],
    "corrupt": [("at", _int, True), ("mask", _int, False)],
    "truncate": [("tail", int, True)],
    "delay": [("seconds", float, True)],
    "cut": [],
}


@dataclass(frozen=True)
class Command:
    """One tap command, from words (`parse_command`) or JSON (`from_json`); `to_json()` is what
    goes over the control port."""

    verb: str
    direction: str | None = None  # normalised a>b, None = both
    fault: Fault | None = None
    data: bytes = b""
    history: bool = False

    def to_json(self) -> dict[str, Any]:
        if self.fault is not None:
            return self.fault.to_json()
        out: dict[str, Any] = {"cmd": self.verb}
        if self.direction is not None:
            out["direction"] = self.direction
        if self.verb == "send":
            out["hex"] = self.data.hex()
        if self.verb == "subscribe":
            out["history"] = self.history
        return out

    def words(self) -> str:
        """The command as words (what a tap's events and answers show)."""
        if self.fault is not None:
            return self.fault.command()
        if self.verb == "send":
            return f"send {self.direction} {self.data.hex()}"
        return self.verb + (f" {self.direction}" if self.direction else "")

    @classmethod
    def from_json(cls, obj: Mapping[str, object]) -> Command:
        verb = obj.get("cmd")
        if not isinstance(verb, str) or verb not in VERBS:
            raise UsageError(f"unknown command {verb!r}; try: {', '.join(VERBS)}")
        if verb in FAULTS:
            fault = fault_from_json(obj)
            return cls(verb, fault.direction, fault)
        direction = obj.get("direction")
        if direction is not None and not isinstance(direction, str):
            raise UsageError(f'{verb}: direction must be a string like "a>b", not {direction!r}')
        if verb == "send":
            text = obj.get("hex")
            try:
                data = bytes.fromhex(text) if isinstance(text, str) else b""
            except ValueError:
                data = b""
            if not data or direction is None:
                raise UsageError('send: give "direction" and the bytes as "hex"')
            return cls(verb, direction, data=data)
        if verb == "subscribe":
            history = obj.get("history", False)
            if not isinstance(history, bool):
                raise UsageError(f"subscribe: history must be true or false, not {history!r}")
            return cls(verb, history=history)
        return cls(verb, direction)


def parse_direction(word: str, names: tuple[str, str] | None = None) -> str | None:
    """`a->b`/`a>b` -> "a>b" (checked against the tap's end names when given); `both`/`*` ->
    None."""
    if word.lower() in ("both", "*", "all"):
        return None
    pair = split_direction(word)
    if pair is None or pair[0] == pair[1] or (names is not None and set(pair) != set(names)):
        a, b = names or ("a", "b")
        raise UsageError(f"bad direction {word!r}: use {a}->{b}, {b}->{a} or both")
    return f"{pair[0]}>{pair[1]}"


def parse_command(line: str, names: tuple[str, str] | None = None) -> Command:
    """Words -> a Command. Without `names` a direction is checked for its form only (the tap
    checks that it has that direction)."""
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
        if args and args != ["history"]:
            raise UsageError(f"subscribe: unexpected arguments {' '.join(args)}")
        return Command(verb, history=bool(args))
    if verb in ("garbage", "send"):
        data = hex_bytes(" ".join(args))
        if not data:
            raise UsageError(f"{verb}: give the bytes in hex, e.g. {verb} a->b 02 ff 00")
        if verb == "send":
            if direction is None:
                raise UsageError("send: give the direction, e.g. send a->b 02 00 ...")
            return Command(verb, direction, data=data)
        return Command.from_json({"cmd": verb, "hex": data.hex(), "direction": direction})
    if verb in TAP_VERBS:
        if args:
            raise UsageError(f"{verb}: unexpected arguments {' '.join(args)}")
        return Command(verb, direction)
    spec = _FAULT_ARGS[verb]
    if len(args) > len(spec):
        raise UsageError(f"{verb}: unexpected arguments {' '.join(args[len(spec) :])}")
    fields: dict[str, object] = {"cmd": verb, "direction": direction}
    for i, (name, convert, required) in enumerate(spec):
        if i >= len(args):
            if required:
                raise UsageError(f"{verb}: give the {name}, e.g. {_example(verb)}")
            continue
        try:
            fields[name] = convert(args[i])
        except ValueError:
            raise UsageError(f"{verb}: {args[i]!r} is not a number") from None
    return Command.from_json(fields)


def _example(verb: str) -> str:
    return next((x.strip().split("  ")[0] for x in HELP.splitlines()
                 if x.strip().startswith(verb + " ")), verb)  # fmt: skip
