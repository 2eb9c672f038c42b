"""Issue 13 item 3: only the operator operates the railway. Every control port of a real lab --
a device's, the lab's, a tap's, and the rails -- obeys only who presents the lab's token, kept in
a file only its owner can read; without it or with a wrong one a request is refused and nothing is
done. The package's own clients find the token themselves. The console takes websockets from its
own pages and from the lab file's allow-list only."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from .conftest import RunningLab, start_lab, token_for

ALLOWED = "http://ctc.lab.example:8020"
OTHER_TOKEN = "ab" * 32


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    tmp = tmp_path_factory.mktemp("accesslab")
    with start_lab(tmp, "accesslab", origins=f"[{ALLOWED}]") as lab:
        yield lab


def conversation(address: str, lines: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Send JSON lines on one connection; the answer to each, in order (a server answers the
    lines of a connection one after the other)."""
    host, _, port = address.rpartition(":")
    with socket.create_connection((host, int(port)), timeout=20) as sock:
        sock.sendall(b"".join(json.dumps(obj).encode() + b"\n" for obj in lines))
        replies = sock.makefile("rb")
        return [json.loads(replies.readline()) for _ in lines]


def refused(answer: dict[str, Any], why: str) -> bool:
    return answer.get("refused") is True and answer["ok"] is False and why in answer["error"]


def test_the_lab_token_is_a_file_only_its_owner_reads(lab: RunningLab) -> None:
    path = Path(lab.state()["token_file"])
    assert path == lab.run_dir / "labs" / "accesslab" / "token"
    st = path.stat()
    assert st.st_uid == os.getuid() and stat.S_IMODE(st.st_mode) == 0o600
    assert len(path.read_text().strip()) == 64
    assert token_for(lab.device("ctc")) == path.read_text().strip()


def test_device_port_refuses_without_or_with_a_wrong_token_and_does_nothing(
    lab: RunningLab,
) -> None:
    ctc = lab.device("ctc")
    route = {"cmd": "route", "action": "set", "station": 20, "entry": "01", "exit": "11"}
    none, wrong, log = conversation(
        ctc, [route, {**route, "token": OTHER_TOKEN}, {"cmd": "log", "token": token_for(ctc)}]
    )
    assert refused(none, "no token") and refused(wrong, "wrong token")
    assert log["ok"] and log["log"] == [], "a refused command reached the CTC"
    assert lab.ctc({"cmd": "show", "station": 20})["summary"]["routes"] == []
    # the operator's own client finds the token and is obeyed
    run = lab.cli("ctc", "--lab", "accesslab", "--json", "route", "set", "20", "01", "11")
    assert run.returncode == 0 and json.loads(run.stdout)["ok"], run.stdout + run.stderr
    run = lab.cli("ctc", "--lab", "accesslab", "route", "cancel", "20", "01", "11")
    assert run.returncode == 0, run.stdout + run.stderr


def test_lab_port_refuses_and_the_device_lives_on(lab: RunningLab) -> None:
    kill = {"cmd": "kill", "device": "atc18"}
    no, wrong, status = conversation(
        lab.control,
        [kill, {**kill, "token": OTHER_TOKEN}, {"cmd": "status", "token": token_for(lab.control)}],
    )
    assert refused(no, "no token") and refused(wrong, "wrong token")
    atc = status["status"]["devices"]["atc18"]
    assert atc["alive"] and atc["crashed"] is None
    run = lab.cli("lab", "status", "accesslab", "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["lab"] == "accesslab", run.stderr


def test_tap_port_refuses_until_the_token_is_presented(lab: RunningLab) -> None:
    """A tap's control port is the devices' JSON-lines server: the same token check."""
    tap = lab.links["st18-atc"]["tap"]
    cut = {"cmd": "cut"}
    none, wrong, still, admitted, status = conversation(
        tap, [cut, {**cut, "token": OTHER_TOKEN}, cut, {"token": token_for(tap)}, {"cmd": "status"}]
    )
    assert refused(none, "no token") and refused(wrong, "wrong token")
    assert refused(still, "no token")  # a wrong token admits nothing
    assert admitted == {"ok": True}
    directions = status["status"]["directions"].values()
    assert not any(d["cut"] for d in directions), "a refused cut was applied"
    run = lab.cli("tap", "status", "st18-atc")
    assert run.returncode == 0 and json.loads(run.stdout)["name"] == "st18-atc", run.stderr


def test_rails_refuse_a_stranger(lab: RunningLab) -> None:
    rails = lab.state()["devices"]["tc"]["listen"]
    fail = {"cmd": "fail", "tc": "TC2051", "kind": "dead"}
    hello = {"hello": {"role": "observer", "name": "stranger"}}
    answers = conversation(
        rails, [hello, fail, {**hello, "token": token_for(lab.device("tc"))}, {"cmd": "status"}]
    )
    assert refused(answers[0], "no token") and refused(answers[1], "no token")
    assert answers[2].get("full") is True  # admitted: the whole occupancy
    assert answers[3]["status"]["faults"] == {}, "a refused fault was applied"


def test_clients_with_a_wrong_or_unsafe_token_file_are_told(
    lab: RunningLab, tmp_path: Path
) -> None:
    wrong = tmp_path / "wrong-token"
    wrong.write_text(OTHER_TOKEN + "\n")
    wrong.chmod(0o600)
    for args in (("ctc", "--lab", "accesslab", "show", "18"), ("tap", "status", "st18-atc"),
                 ("lab", "status", "accesslab"), ("monitor", "st18-atc", "--count", "1")):  # fmt: skip
        run = lab.cli(*args, env={"KTCS_BENCH_TOKEN_FILE": str(wrong)})
        assert run.returncode == 3, (args, run.stdout, run.stderr)
        assert "refused: wrong token" in run.stderr and "Traceback" not in run.stderr, run.stderr
    wrong.chmod(0o644)
    run = lab.cli(
        "ctc", "--lab", "accesslab", "show", "18", env={"KTCS_BENCH_TOKEN_FILE": str(wrong)}
    )
    assert run.returncode == 2 and "may be read by others" in run.stderr, run.stderr


async def _ws(url: str, origin: str) -> str:
    async with asyncio.timeout(20), aiohttp.ClientSession() as session:
        try:
            async with session.ws_connect(url, origin=origin) as ws:
                hello = json.loads((await ws.receive()).data)
                return str(hello["type"])
        except aiohttp.WSServerHandshakeError as exc:
            return f"refused {exc.status}"


def test_lab_console_takes_its_own_and_the_allowed_origins_only(lab: RunningLab) -> None:
    console = lab.state()["devices"]["ctc"]["console"]  # http://127.0.0.1:PORT/
    ws = console.replace("http://", "ws://") + "ws"
    own = console.rstrip("/")
    assert asyncio.run(_ws(ws, own)) == "hello"
    assert asyncio.run(_ws(ws, ALLOWED)) == "hello"
    assert asyncio.run(_ws(ws, "http://evil.example")) == "refused 403"
