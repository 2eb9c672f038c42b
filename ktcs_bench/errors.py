"""The package's typed errors, split by whose fault they are (the h11 way).

`PeerError` means the bytes or the device on the other end misbehaved; `UsageError` means we were
asked for something illegal; `ConfigError` means a data file (YAML) is wrong. Everything the package
raises on purpose derives from `KtcsError`, so a tool can catch one type and exit cleanly.
"""

from __future__ import annotations

import reprlib
from pathlib import Path

EXCERPT_CHARS = 60
"""The most of a value (its repr) an error message quotes: a file's value may be megabytes."""
MAX_PROBLEM_CHARS = 1000
"""A ConfigError's problem is cut here, whatever it quotes (the last guard behind `excerpt`)."""

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxset = 3, 4, 4, 4, 4
_REPR.maxstring, _REPR.maxlong, _REPR.maxother = EXCERPT_CHARS, EXCERPT_CHARS, EXCERPT_CHARS


def excerpt(value: object, limit: int = EXCERPT_CHARS) -> str:
    """`repr(value)` cut to about `limit` characters ("..." marks the cut). The repr is built
    bounded (a few items of a few levels), so a huge or deeply shared value costs nothing."""
    try:
        text = _REPR.repr(value)
    except ValueError:  # an int past Python's 4300 digits
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def kind_of(value: object) -> str:
    """What a parsed YAML value is, in a user's words: nothing, true/false, a number, text, a
    list, a mapping (else its type's name)."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "text"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


class KtcsError(Exception):
    """Base of every error ktcs-bench raises on purpose."""


class PeerError(KtcsError):
    """The peer (or the input bytes) broke the protocol."""


class UsageError(KtcsError):
    """The caller asked for something the protocol or the tool does not allow."""


class ConfigError(KtcsError):
    """A data file is wrong: names the file, the place in it (a key path) and the problem.

    A message quotes a value of the file through `excerpt`; a problem longer than
    `MAX_PROBLEM_CHARS` is cut all the same (one line of a terminal, not the file's megabytes)."""

    def __init__(self, file: str | Path, place: str, problem: str) -> None:
        self.file = str(file)
        if len(place) > MAX_PROBLEM_CHARS // 4:  # a key path holds the file's keys
            place = f"{place[: MAX_PROBLEM_CHARS // 4 - 3]}..."
        self.place = place
        if len(problem) > MAX_PROBLEM_CHARS:
            problem = f"{problem[: MAX_PROBLEM_CHARS - 3]}..."
        self.problem = problem
        where = f"{self.file}: {place}" if place else self.file
        super().__init__(f"{where}: {problem}")


def say_seconds(value: float) -> str:
    """A bound in seconds as a person reads it: 86400 -> '24 h (86400 s)', 90 -> '90 s'."""
    for unit, size in (("h", 3600.0), ("min", 60.0)):
        if value >= size and value % size == 0:
            return f"{value / size:.10g} {unit} ({value:.10g} s)"
    return f"{value:.10g} s"
