"""Where running taps announce themselves, so `tap fault NAME`, `monitor NAME` and `replay --to
NAME` find a tap by name: one JSON file per named tap in the run directory.

The run directory is $KTCS_BENCH_RUN_DIR, else $XDG_RUNTIME_DIR/ktcs-bench, else
/tmp/ktcs-bench-<uid>. A tap may also be addressed by its control address: `HOST:PORT`, `PORT` or
`tap://HOST:PORT`.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any

from ktcs_bench.emulator.endpoints import check_port
from ktcs_bench.errors import UsageError

_ADDRESS = re.compile(r"^(?:tap://)?(?:(?P<host>[\w.:-]+|\[[0-9a-fA-F:]+\]):)?(?P<port>\d{1,5})$")


def run_dir() -> Path:
    if "KTCS_BENCH_RUN_DIR" in os.environ:
        return Path(os.environ["KTCS_BENCH_RUN_DIR"])
    if "XDG_RUNTIME_DIR" in os.environ:
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "ktcs-bench"
    return Path(tempfile.gettempdir()) / f"ktcs-bench-{os.getuid()}"


def tap_file(name: str) -> Path:
    if not re.fullmatch(r"[\w.-]+", name):
        raise UsageError(f"tap name {name!r}: use letters, digits, '.', '-', '_'")
    return run_dir() / "taps" / f"{name}.json"


def announce(name: str, info: dict[str, Any]) -> Path:
    path = tap_file(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def withdraw(name: str) -> None:
    try:
        tap_file(name).unlink()
    except FileNotFoundError:
        pass


def known_taps() -> list[dict[str, Any]]:
    folder = run_dir() / "taps"
    out = []
    for p in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            out.append(json.loads(p.read_text(encoding="utf-8")))
        except (OSError, ValueError):
            continue
    return out


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
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
        host, port = info["control"]
        return str(host), int(port)
    except FileNotFoundError:
        raise UsageError(f"no tap named {name!r} (looked in {path.parent})") from None
    except (OSError, ValueError, KeyError, TypeError):
        raise UsageError(f"tap file {path} is unreadable") from None
