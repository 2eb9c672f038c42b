"""Running the generated dissector in real tshark, and comparing it with `ktcs-bench decode --json`.

Every tshark run gets its own HOME, so a dissector the user installed (or their preferences) never
joins in; `-2` gives the dissector the whole capture (a record is shown in the packet holding its
last byte, a frame cut off by the end of the capture is reported truncated).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.capture import CaptureRecord
from ktcs_bench.capture.pcapng import PcapngEncoder

Rec = dict[str, Any]


def tshark() -> str:
    path = shutil.which("tshark")
    if path is None:
        pytest.fail(
            "tshark is not installed: the dissector tests need it "
            "(Debian: apt-get install -y tshark) -- they must not be skipped"
        )
    return path


def cli(*args: str, stdin: str | None = None, env: dict[str, str] | None = None,
        timeout: float = 120) -> subprocess.CompletedProcess[str]:  # fmt: skip
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args], input=stdin, capture_output=True,
        text=True, timeout=timeout, env={**os.environ, **(env or {})},
    )  # fmt: skip


def make_dissector(path: Path, *extra: str) -> Path:
    done = cli("dissector", "--out", str(path), *extra)
    assert done.returncode == 0, done.stderr
    return path


def run_tshark(
    lua: Path | None, capture: Path, *args: str, home: Path | None = None
) -> subprocess.CompletedProcess[str]:
    home = home or capture.parent / "tshark-home"
    home.mkdir(exist_ok=True)
    cmd = [tshark(), "-2", "-r", str(capture), *args]
    if lua is not None:
        cmd[1:1] = ["-X", f"lua_script:{lua}"]
    env = {**os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home / ".config")}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)


def tshark_json(lua: Path | None, capture: Path, *args: str, home: Path | None = None) -> list[Any]:
    done = run_tshark(lua, capture, "-T", "json", "--no-duplicate-keys", *args, home=home)
    assert done.returncode == 0, done.stderr
    assert "Lua Error" not in done.stdout + done.stderr, done.stdout[-3000:] + done.stderr
    packets: list[Any] = json.loads(done.stdout or "[]")
    return packets


def write_pcapng(path: Path, records: Iterable[CaptureRecord], link: str) -> Path:
    """With the bench's own writer (Type II end `ctc` at 127.0.0.1:5020)."""
    enc = PcapngEncoder(link, {"ctc": ("127.0.0.1", 5020)} if link == "type2" else None)
    path.write_bytes(enc.start() + b"".join(enc.encode(r) for r in records))
    return path


def _list(value: Any) -> list[Any]:
    if value is None:
        return []
    return value if isinstance(value, list) else [value]


def _int(value: str) -> int:
    return int(value, 0)


def from_tree(t: dict[str, Any], short: str) -> Rec | None:
    """One ktcs1/ktcs2 protocol tree of `tshark -T json` as a record in decode's terms."""
    x = short + "."
    if x + "offset" not in t:
        return None  # the note in a packet holding bytes of a record shown elsewhere
    offset = _int(t[x + "offset"])
    if x + "garbage" in t:
        return {"offset": offset, "garbage": t[x + "garbage"].replace(":", "")}
    errors = _list(t.get(x + "error"))
    items: list[list[int]] | None = None
    if x + "item" in t:  # FT_NONE items: tshark puts each one's subtree under its key
        items = [[_int(v) for v in tree.values()] for tree in _list(t[x + "item"])]
    elif x + "status" in t:
        items = [[k + 1, _int(v)] for k, v in enumerate(_list(t[x + "status"]))]
    elif x + "items" in t:
        items = []  # an opcode that carries items, with none
    return {
        "offset": offset,
        "seq": _int(t[x + "seq"]) if x + "seq" in t else None,
        "op": _int(t[x + "op"]) if x + "op" in t else None,
        "sub": _int(t[x + "sub"]) if x + "sub" in t else None,
        "data": t.get(x + "data", "").replace(":", ""),
        "items": items,
        "crc_ok": t[x + "crc_ok"] == "1",
        "crc_packet": _int(t[x + "crc"]) if x + "crc" in t else None,
        "crc_calc": _int(t[x + "crc_calc"]) if x + "crc_calc" in t else None,
        "error": errors[0] if errors else None,
    }


def dissected(packets: list[Any], short: str) -> dict[str, list[Rec]]:
    """Records per direction (the packet comment the bench's pcapng writer puts on every packet),
    in the order tshark shows them."""
    out: dict[str, list[Rec]] = defaultdict(list)
    for packet in packets:
        layers = packet["_source"]["layers"]
        direction = layers.get("pkt_comment", {}).get("frame.comment", "?")
        for tree in _list(layers.get(short)):
            rec = from_tree(tree, short)
            if rec is not None:
                out[direction].append(rec)
    return dict(out)


KEYS = ("offset", "seq", "op", "sub", "data", "items", "crc_ok", "crc_packet", "crc_calc", "error")


def as_record(obj: dict[str, Any]) -> Rec:
    """A `decode --json` object as a record: garbage, or the keys a dissected frame has."""
    if "garbage" in obj:
        return {"offset": obj["offset"], "garbage": obj["garbage"]}
    return {k: obj[k] for k in KEYS}


def decoded(stream: bytes, profile: str) -> list[Rec]:
    """`ktcs-bench decode --json` of one direction's bytes, as records."""
    if not stream:
        return []
    done = cli("decode", "--json", "--profile", profile, "-", stdin=stream.hex())
    assert done.returncode in (0, 1), done.stderr
    return [as_record(json.loads(line)) for line in done.stdout.splitlines()]


def streams(records: Iterable[CaptureRecord], key: Any = None) -> dict[str, bytes]:
    out: dict[str, bytearray] = defaultdict(bytearray)
    for r in records:
        out[key(r) if key else r.direction] += r.data
    return {k: bytes(v) for k, v in out.items()}


def assert_agree(dissector: dict[str, list[Rec]], python: dict[str, list[Rec]]) -> None:
    """Frame by frame, every direction: the same records, error frames and garbage included."""
    assert sorted(dissector) == sorted(k for k, v in python.items() if v), (
        sorted(dissector),
        sorted(python),
    )
    for direction, want in python.items():
        got = dissector.get(direction, [])
        for k, (a, b) in enumerate(zip(got, want, strict=False)):
            assert a == b, f"{direction}: record {k} differs:\n tshark {a}\n decode {b}"
        assert len(got) == len(want), f"{direction}: {len(got)} records in tshark, {len(want)}"
