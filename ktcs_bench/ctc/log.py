"""The CTC's command log: every operator command, in the words the operator types, and what came
of it (pure: the caller gives the time)."""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any, Literal, NotRequired, TypedDict

from ktcs_bench.ctc.model import signal_name
from ktcs_bench.errors import UsageError
from ktcs_bench.messages import (
    Ars,
    AskDirection,
    Control,
    Log,
    Message,
    Mode,
    Point,
    Route,
    Show,
    Signal,
    Status,
    encode,
)

KEEP = 10_000  # entries kept


def command_words(command: Message | Mapping[str, Any]) -> str:
    """An operator command as the operator types it to `ktcs-bench ctc` ("route set 18 01 11");
    a command of another shape as its keys and values."""
    if isinstance(command, Message):
        command = encode(command)
    cmd, st = str(command.get("cmd", "?")), command.get("station", "?")

    def sig(key: str) -> str:
        return signal_name(str(command.get(key, "?")))

    if cmd == "route":
        exit_ = f" {sig('exit')}" if "exit" in command else ""
        return f"route {command.get('action', 'set')} {st} {sig('entry')}{exit_}"
    if cmd == "point":
        return f"point {command.get('position', '?')} {st} {command.get('point', '?')}"
    if cmd == "signal":
        return f"signal {command.get('action', 'stop')} {st} {sig('signal')}"
    if cmd == "mode":
        return f"mode {command.get('mode', '?')} {st}"
    if cmd == "direction":
        return f"direction {st} {command.get('interval', '?')}"
    if cmd == "control":
        return f"control {st} {command.get('code', '?')} {command.get('value', 1)}"
    return " ".join([cmd, *(f"{k}={v}" for k, v in command.items() if k != "cmd")])


def parse_words(words: list[str]) -> Message:
    """Operator words (as `ktcs-bench ctc` takes them: `route set 18 S1 S11`) -> the CTC control
    port's message (`messages.CTC`), the inverse of `command_words`. UsageError with a hint when
    malformed."""
    if not words:
        raise UsageError("empty command")
    w = [x.lower() for x in words]
    try:
        if w[0] == "route" and w[1] in ("set", "cancel") and len(w) == 5:
            action: Literal["set", "cancel"] = "set" if w[1] == "set" else "cancel"
            return Route(action=action, station=int(w[2]), entry=words[3], exit=words[4])
        if w[0] == "point" and w[1] in ("normal", "reverse") and len(w) == 4:
            return Point(position=w[1], station=int(w[2]), point=words[3])
        if w[0] == "signal" and w[1] in ("stop", "release") and len(w) == 4:
            return Signal(action=w[1], station=int(w[2]), signal=words[3])
        if w[0] == "mode" and w[1] in ("center", "local") and len(w) == 3:
            return Mode(mode=w[1], station=int(w[2]))
        if w[0] == "direction" and len(w) == 3:
            return AskDirection(station=int(w[1]), interval=words[2])
        if w[0] == "control" and len(w) in (3, 4):
            value = int(w[3], 0) if len(w) == 4 else 1
            return Control(station=int(w[1]), code=words[2].upper(), value=value)
        if w[0] == "show" and len(w) == 2:
            return Show(station=int(w[1]))
        if w[0] == "status" and len(w) == 1:
            return Status()
        if w[0] == "log" and len(w) == 1:
            return Log()
        if w[0] == "ars" and len(w) == 1:
            return Ars()
        if w[0] == "ars" and w[1] in ("on", "off") and len(w) in (2, 3):
            return Ars(on=w[1] == "on", station=int(w[2]) if len(w) == 3 else None)
    except (IndexError, ValueError):
        pass
    raise UsageError(f"cannot read {' '.join(words)!r}; type `help`")


class LogEntry(TypedDict):
    """One command in the log (its JSON object as `ctc log` shows it)."""

    time: float  # when it was given, on the lab's clock
    command: str  # in the operator's words (`command_words`)
    source: str  # who gave it: ctc, console, ars
    result: NotRequired[str]  # once known: accepted, rejected: REASON, refused ..., no result ...
    code: NotRequired[str]  # the control code it went out as
    seconds: NotRequired[float]  # CONTROL -> CONTROL_RESULT


class CommandLog:
    """Entries (`LogEntry`) `{"time", "command", "source"}`, completed with "result" (and, for a
    command that went out, "code" and "seconds") once known. Newest last; the oldest beyond `keep`
    drop out."""

    def __init__(self, keep: int = KEEP) -> None:
        self.entries: deque[LogEntry] = deque(maxlen=keep)

    def record(self, time: float, command: Message | Mapping[str, Any], source: str) -> LogEntry:
        entry = LogEntry(time=time, command=command_words(command), source=source)
        self.entries.append(entry)
        return entry

    def last(self, count: int) -> list[LogEntry]:
        return list(self.entries)[-count:] if count > 0 else []
