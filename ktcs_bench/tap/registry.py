"""Where running taps announce themselves, so `tap fault NAME`, `monitor NAME` and `replay --to
NAME` find a tap by name: one JSON file per named tap in the run folder (`ktcs_bench.runtime`),
stamped with the process that holds the tap. A file whose process is gone (a lab killed with
SIGKILL cannot withdraw its taps) names a dead tap: it is dropped when the taps are listed or the
name is looked up. A tap may also be addressed by its control address: `HOST:PORT`, `PORT` or
`tap://HOST:PORT`.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Required, TypedDict, cast

from ktcs_bench.errors import UsageError
from ktcs_bench.runtime import private_dir, process_alive, run_dir, this_process
from ktcs_bench.transport.endpoints import check_port


class TapEnds(TypedDict, total=False):
    """Where a tap's ends are, as its info says: each kind of tap its own keys."""

    paths: dict[str, str]  # pty: the pty path of each end it made; wire: each end's endpoint
    external: dict[str, str]  # pty: the serial endpoint of each external end
    listen: list[str | int]  # tcp: [host, port] it listens at
    target: list[str | int]  # tcp: [host, port] it connects to


class TapInfo(TapEnds, total=False):
    """What a user needs to reach a tap (printed by `tap run`, announced by name)."""

    name: Required[str | None]
    kind: Required[str]
    profile: Required[str]
    protocol: Required[str]
    names: Required[list[str]]
    control: Required[list[str | int] | None]
    token_file: Required[str]
    pid: Required[int]


class Announcement(TapInfo):
    """A named tap's registry file: its info, and when its process started (`this_process`)."""

    started: int | None


_ADDRESS = re.compile(r"^(?:tap://)?(?:(?P<host>[\w.:-]+|\[[0-9a-fA-F:]+\]):)?(?P<port>\d{1,5})$")


def tap_file(name: str) -> Path:
    if not re.fullmatch(r"[\w.-]+", name):
        raise UsageError(f"tap name {name!r}: use letters, digits, '.', '-', '_'")
    return run_dir() / "taps" / f"{name}.json"


def announce(name: str, info: TapInfo) -> Path:
    path = tap_file(name)
    private_dir(path.parent)
    tmp = path.with_suffix(f".{this_process()['pid']}.tmp")
    tmp.write_text(json.dumps({**info, **this_process()}, indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def withdraw(name: str) -> None:
    """Remove the announcement of tap `name` if this process made it (or its maker is gone)."""
    path = tap_file(name)
    info = _live(path)
    if info is not None and info.get("pid") == this_process()["pid"]:
        path.unlink(missing_ok=True)


def _live(path: Path) -> Announcement | None:
    """The tap a registry file announces, or None -- and the file removed -- if the process that
    held the tap is gone."""
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        info = None
    if not isinstance(info, dict) or not process_alive(
        int(info.get("pid") or 0), info.get("started")
    ):
        path.unlink(missing_ok=True)
        return None
    return cast(Announcement, info)  # as `announce` wrote it; its readers check what they use


def known_taps() -> list[Announcement]:
    """The named taps whose process still runs (the files of dead ones are dropped)."""
    folder = run_dir() / "taps"
    found = (_live(p) for p in sorted(folder.glob("*.json"))) if folder.is_dir() else ()
    return [info for info in found if info is not None]


def parse_tap_address(
    spec: str, what: str = "tap address", *, any_free: bool = False
) -> tuple[str, int] | None:
    """`[tap://][HOST:]PORT` -> (host, port), the port range-checked; None if `spec` is no address
    (a tap name)."""
    m = _ADDRESS.match(spec)
    if not m:
        return None
    host = (m.group("host") or "127.0.0.1").strip("[]")
    return host, check_port(m.group("port"), f"{what} {spec}", any_free=any_free)


def resolve_tap(spec: str) -> tuple[str, int]:
    """A tap's control address from `HOST:PORT`, `PORT`, `tap://HOST:PORT` or a tap name."""
    addr = parse_tap_address(spec)
    if addr is not None:
        return addr
    name = spec.removeprefix("tap://")
    path = tap_file(name)
    info = _live(path)
    if info is None:
        raise UsageError(f"no tap named {name!r} runs (looked in {path.parent})")
    control = info.get("control")
    try:
        if control is None:
            raise ValueError("no control port")
        host, port = control
        return str(host), int(port)
    except (TypeError, ValueError):
        raise UsageError(f"tap file {path} is unreadable") from None
