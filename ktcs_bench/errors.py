"""The package's typed errors, split by whose fault they are (the h11 way).

`PeerError` means the bytes or the device on the other end misbehaved; `UsageError` means we were
asked for something illegal; `ConfigError` means a data file (YAML) is wrong. Everything the package
raises on purpose derives from `KtcsError`, so a tool can catch one type and exit cleanly.
"""

from __future__ import annotations

from pathlib import Path


class KtcsError(Exception):
    """Base of every error ktcs-bench raises on purpose."""


class PeerError(KtcsError):
    """The peer (or the input bytes) broke the protocol."""


class UsageError(KtcsError):
    """The caller asked for something the protocol or the tool does not allow."""


class ConfigError(KtcsError):
    """A data file is wrong: names the file, the place in it (a key path) and the problem."""

    def __init__(self, file: str | Path, place: str, problem: str) -> None:
        self.file = str(file)
        self.place = place
        self.problem = problem
        where = f"{self.file}: {place}" if place else self.file
        super().__init__(f"{where}: {problem}")
