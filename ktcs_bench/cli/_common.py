"""Small pieces every subcommand shares: colour on a terminal, reading hex input, JSON lines."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any, TextIO

from ktcs_bench.errors import UsageError


def use_colour(stream: TextIO, flag: bool | None = None) -> bool:
    """Colour where a person watches: a tty, not NO_COLOR, unless forced either way."""
    if flag is not None:
        return flag
    return stream.isatty() and "NO_COLOR" not in os.environ


def read_text_inputs(inputs: list[str]) -> str:
    """Arguments that name files are read; '-' (or nothing, with a pipe) reads stdin; else hex text."""
    if not inputs:
        if sys.stdin.isatty():
            raise UsageError("no input: give hex text, a capture file, or pipe it on stdin")
        return sys.stdin.read()
    parts = []
    for item in inputs:
        if item == "-":
            parts.append(sys.stdin.read())
            continue
        path = Path(item)
        if path.is_file():
            try:
                parts.append(path.read_text(encoding="utf-8", errors="replace"))
            except OSError as exc:
                raise UsageError(f"cannot read {item}: {exc.strerror}") from None
        else:
            parts.append(item)
    return "\n".join(parts)


def print_json_line(obj: dict[str, Any], stream: TextIO = sys.stdout) -> None:
    stream.write(json.dumps(obj, ensure_ascii=False, separators=(", ", ": ")) + "\n")
