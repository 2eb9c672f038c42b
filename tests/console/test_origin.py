"""Issue 13 item 3: a web page from anywhere else cannot operate the railway through the console.
A real websocket client (aiohttp) offers the Origin a browser would send: the console's own
origin is served and its route requests carried out; a foreign one -- another site, another
port, a DNS name pointed at 127.0.0.1 (rebinding) -- is refused at the handshake (403), so not a
single request of it reaches the CTC. Origins named in the allow-list are served too."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import aiohttp
import pytest

from ktcs_bench.console.server import ConsoleServer

from .conftest import Bench


async def operate(
    url: str, origin: str | None, request: dict[str, Any], host: str | None = None
) -> dict[str, Any] | str:
    """Connect as a page of `origin` would (None: no Origin, as a non-browser tool), send one
    request, return its result -- or "refused STATUS" if the handshake is refused."""
    headers = {"Host": host} if host else {}
    async with asyncio.timeout(20), aiohttp.ClientSession() as session:
        try:
            async with session.ws_connect(url, origin=origin, headers=headers) as ws:
                await ws.send_str(json.dumps({**request, "id": 1}))
                async for msg in ws:
                    data = json.loads(msg.data)
                    if data.get("type") == "result":
                        return data  # type: ignore[no-any-return]
        except aiohttp.WSServerHandshakeError as exc:
            return f"refused {exc.status}"
    raise AssertionError("the console closed without a result")


def ws_url(console: ConsoleServer) -> str:
    return console.url.replace("http://", "ws://") + "ws"


def test_own_origin_operates_a_foreign_one_is_refused_before_any_request(bench: Bench) -> None:
    url, port = ws_url(bench.console), bench.console.port
    set_route = {"type": "route_set", "station": 20, "entry": "01", "exit": "11"}
    before = len(bench.console.log_entries)
    for origin, host in (
        ("http://evil.example", None),  # another site
        (f"http://127.0.0.1:{port + 1}", None),  # another port on this machine
        (f"http://rebound.example:{port}", f"rebound.example:{port}"),  # DNS rebinding
        ("null", None),  # a sandboxed page or a file:// one
    ):
        assert asyncio.run(operate(url, origin, set_route, host)) == "refused 403", origin
    assert len(bench.console.log_entries) == before, "a refused page's request was carried out"
    assert bench.do(lambda: bench.rigs[20].rig.ctc["RSI200111"]) == 0
    for origin in (f"http://127.0.0.1:{port}", f"http://localhost:{port}"):
        result = asyncio.run(operate(url, origin, set_route))
        assert isinstance(result, dict) and result["ok"], result
        assert bench.do(lambda: bench.rigs[20].rig.ctc["RSI200111"]) == 1
        cancel = {"type": "route_cancel", "station": 20, "entry": "01", "exit": "11"}
        assert isinstance(r := asyncio.run(operate(url, origin, cancel)), dict) and r["ok"], r


@pytest.mark.parametrize(
    ("origin", "served"),
    [
        ("http://ctc.lab.example:8020", True),
        ("HTTP://CTC.LAB.EXAMPLE:8020/", True),
        ("http://ctc.lab.example:8021", False),
        ("https://ctc.lab.example:8020", False),
    ],
)
def test_the_allow_list_adds_origins(bench: Bench, origin: str, served: bool) -> None:
    async def start() -> ConsoleServer:
        console = ConsoleServer(bench.console.desk, origins=["http://ctc.lab.example:8020"])
        await console.start()
        return console

    console = bench.call(start())
    try:
        show = {"type": "mode", "station": 18, "mode": "center"}
        result = asyncio.run(operate(ws_url(console), origin, show))
        assert (result != "refused 403") is served, result
    finally:
        bench.call(console.close())


def test_a_tool_that_sends_no_origin_is_served(bench: Bench) -> None:
    """No browser omits Origin on a websocket; a local tool may (and could forge any)."""
    result = asyncio.run(operate(ws_url(bench.console), None, {"type": "mode", "station": 18,
                                                                "mode": "center"}))  # fmt: skip
    assert isinstance(result, dict), result
