"""The CTC's command log: every operator command, in the words the operator types, and what came
of it (pure: the caller gives the time)."""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any

from ktcs_bench.ctc.model import signal_name

KEEP = 10_000  # entries kept


def command_words(command: Mapping[str, Any]) -> str:
    """An operator command as the operator types it to `ktcs-bench ctc` ("route set 18 01 11");
    a command of another shape as its keys and values."""
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
    if cmd == "control":
        return f"control {st} {command.get('code', '?')} {command.get('value', 1)}"
    return " ".join([cmd, *(f"{k}={v}" for k, v in command.items() if k != "cmd")])


class CommandLog:
    """Entries `{"time", "command", "source"}`, completed with "result" (and, for a command that
    went out, "code" and "seconds") once known. Newest last; the oldest beyond `keep` drop out."""

    def __init__(self, keep: int = KEEP) -> None:
        self.entries: deque[dict[str, Any]] = deque(maxlen=keep)

    def record(self, time: float, command: Mapping[str, Any], source: str) -> dict[str, Any]:
        entry: dict[str, Any] = {"time": time, "command": command_words(command), "source": source}
        self.entries.append(entry)
        return entry

    def last(self, count: int) -> list[dict[str, Any]]:
        return list(self.entries)[-count:] if count > 0 else []
