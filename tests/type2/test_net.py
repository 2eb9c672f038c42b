"""Type II over real TCP sockets on 127.0.0.1: CtcServer and IxlClient, with a proxy for faults."""

from __future__ import annotations

import asyncio
import logging
import random

import pytest

from ktcs_bench.ctc.tables import IndicationTables
from ktcs_bench.transport.ctc_server import CtcServer
from ktcs_bench.transport.ixl_client import IxlClient, StateTable
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.admission import AdmissionPolicy
from ktcs_bench.type2.config import Type2Config

from .netutil import CUT, PROFILE, Proxy, damage, poll_until, run

INDICATION = 0x10
HEARTBEAT = 0x40
FAST = dict(backoff_initial=0.02, backoff_max=0.2)


def table(n: int = 1000, seed: int = 1) -> StateTable:
    rnd = random.Random(seed)
    return StateTable({code: rnd.randrange(4) for code in range(1, n + 1)})


class Recorder:
    def __init__(self) -> None:
        self.events: list[tuple[int | None, ev.SessionEvent]] = []

    def __call__(self, station: int | None, event: ev.SessionEvent) -> None:
        self.events.append((station, event))

    def of(self, kind: type) -> list:
        return [e for _, e in self.events if isinstance(e, kind)]


def change(app: StateTable, client: IxlClient, codes: list[int]) -> list[tuple[int, int]]:
    changes = [(c, (app.state[c] + 1) % 4) for c in codes]
    app.state.update(changes)
    client.indicate(changes)
    return changes


def test_ident_accepted_and_full_state_in_parts_of_40_in_chart_order() -> None:
    async def main() -> None:
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table()
            async with IxlClient(20, "127.0.0.1", port, app, **FAST):
                await ctc.wait_until(lambda: tables.stations[20].synced)
                assert tables.stations[20].state == app.state
                assert tables.stations[20].peer is not None
            await proxy.close()
        ind = [f for f in proxy.seen_up if f.op == INDICATION]
        assert [f.sub for f in ind] == [1] * 24 + [2]
        items = PROFILE.opcodes.by_name["INDICATION"].items_of
        assert all(len(items(f.data)) <= 40 for f in ind)
        assert [c for f in ind for c, _ in items(f.data)] == list(range(1, 1001))
        assert proxy.seen_up[0].op == 0x01 and proxy.seen_down[0].sub == 1  # IDENT, accepted

    run(main())


def test_unknown_station_refused_and_logged_with_peer_address(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            async with IxlClient(99, "127.0.0.1", ctc.port, table(5), on_event=rec, **FAST) as c:
                await c.wait_until(lambda: len(rec.of(ev.IdentRefused)) >= 2)
            assert tables.stations[20].connections == 0
            assert ctc.refusals[0][0].startswith("127.0.0.1:")
            assert "station 99 is not configured" in ctc.refusals[0][1]

    with caplog.at_level(logging.WARNING, logger="ktcs_bench.type2"):
        run(main())
    assert any("127.0.0.1:" in r.getMessage() and "99" in r.getMessage() for r in caplog.records)


def test_second_connection_for_the_same_station_is_refused(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            first = IxlClient(20, "127.0.0.1", ctc.port, table(5), **FAST)
            second = IxlClient(20, "127.0.0.1", ctc.port, table(5), on_event=rec, **FAST)
            async with first:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                async with second:
                    await second.wait_until(lambda: len(rec.of(ev.IdentRefused)) >= 1)
                assert first.identified and tables.stations[20].connections == 1
            assert any("already connected" in reason for _, reason in ctc.refusals)

    with caplog.at_level(logging.WARNING, logger="ktcs_bench.type2"):
        run(main())
    assert any("already connected" in r.getMessage() for r in caplog.records)


def test_source_address_allow_list() -> None:
    async def main() -> None:
        policy = AdmissionPolicy([20], allowed_sources=["10.0.0.0/8"])
        tables = IndicationTables(policy.stations)
        async with CtcServer(policy, tables) as ctc:
            async with IxlClient(20, "127.0.0.1", ctc.port, table(5), **FAST) as client:
                await ctc.wait_until(lambda: len(ctc.refusals) >= 2)
                assert not client.identified
            assert "source address 127.0.0.1 is not allowed" in ctc.refusals[0][1]
        policy = AdmissionPolicy([20], station_sources={20: ["127.0.0.0/8"]})
        tables = IndicationTables(policy.stations)
        async with CtcServer(policy, tables) as ctc:
            async with IxlClient(20, "127.0.0.1", ctc.port, table(5), **FAST):
                await ctc.wait_until(lambda: tables.stations[20].synced)

    run(main())


def test_change_indications_reach_the_ctc_state() -> None:
    async def main() -> None:
        tables = IndicationTables([18, 20])
        async with CtcServer([18, 20], tables) as ctc:
            apps = {18: table(300, 18), 20: table(1000, 20)}
            clients = [IxlClient(st, "127.0.0.1", ctc.port, apps[st], **FAST) for st in apps]
            for c in clients:
                c.start()
            await ctc.wait_until(lambda: all(tables.stations[s].synced for s in apps))
            rnd = random.Random(7)
            for _ in range(50):
                for c in clients:
                    change(apps[c.station], c, rnd.sample(range(1, len(apps[c.station].state)), 60))
                await asyncio.sleep(0)
            await ctc.wait_until(
                lambda: all(tables.stations[s].state == apps[s].state for s in apps)
            )
            assert all(tables.stations[s].full_states == 1 for s in apps)
            for c in clients:
                await c.close()

    run(main())


def test_control_and_control_result() -> None:
    async def main() -> None:
        def on_control(code: int, value: int) -> tuple[bool, int]:
            return (True, 0) if code == 7 else (False, 2)

        app = StateTable({1: 0}, on_control)
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            async with IxlClient(20, "127.0.0.1", ctc.port, app, **FAST):
                await ctc.wait_until(lambda: tables.stations[20].synced)
                ok = await ctc.control(20, 7, 1)
                no = await ctc.control(20, 9, 1)
        assert ok == ev.ControlAnswered(7, True, 0, "none")
        assert no == ev.ControlAnswered(9, False, 2, "route conflicts")

    run(main())


def test_nak_then_retransmission_delivers_the_change_once() -> None:
    async def main() -> None:
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables, on_event=rec) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table(100)
            damaged: list[int] = []

            def up(f):  # damage the first change indication once
                if f.op == INDICATION and f.sub == 0 and not damaged:
                    damaged.append(f.seq)
                    return damage(f.raw)
                return f.raw

            proxy.up = up
            async with IxlClient(20, "127.0.0.1", port, app, on_event=rec, **FAST) as c:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                sent = change(app, c, [5, 6, 7])
                await ctc.wait_until(lambda: tables.stations[20].state == app.state)
                assert c.connections == 1
            await proxy.close()
        (bad,) = [e for e in rec.of(ev.BadFrameReceived) if e.nak_sent]
        assert (bad.reason, bad.refused_seq) == (1, damaged[0])
        assert rec.of(ev.Retransmission)[0].seq == damaged[0]
        got = [i for e in rec.of(ev.IndicationsChanged) for i in e.items]
        assert got == sent  # exactly once

    run(main())


def test_three_retransmissions_close_and_the_ixl_reconnects() -> None:
    async def main() -> None:
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables, on_event=rec) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table(100)
            proxy.up = lambda f: damage(f.raw) if f.op == INDICATION and f.sub == 0 else f.raw
            async with IxlClient(20, "127.0.0.1", port, app, on_event=rec, **FAST) as c:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                change(app, c, [5, 6, 7])
                await c.wait_until(lambda: c.connections >= 2)
                proxy.up = None
                await ctc.wait_until(
                    lambda: tables.stations[20].synced and tables.stations[20].state == app.state
                )
            await proxy.close()
        closes = [e.reason for s, e in rec.events if s == 20 and isinstance(e, ev.Closed)]
        assert any("refused after 3 retransmissions" in r for r in closes)
        assert [e.attempt for e in rec.of(ev.Retransmission)][:3] == [1, 2, 3]
        assert rec.of(ev.IndicationsChanged) == []  # the damaged change was never acted on

    run(main())


def test_seq_gap_asks_request_all_and_the_full_state_repairs_the_view() -> None:
    async def main() -> None:
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables, on_event=rec) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table(200)
            dropped: list[int] = []

            def up(f):  # lose one change indication on the way
                if f.op == INDICATION and f.sub == 0 and not dropped:
                    dropped.append(f.seq)
                    return None
                return f.raw

            proxy.up = up
            async with IxlClient(20, "127.0.0.1", port, app, on_event=rec, **FAST) as c:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                change(app, c, [1, 2, 3])
                await poll_until(lambda: bool(dropped))  # that frame is lost; then the next
                change(app, c, [4])
                await ctc.wait_until(lambda: tables.stations[20].full_states >= 2)
                await ctc.wait_until(lambda: tables.stations[20].state == app.state)
                assert c.connections == 1
            await proxy.close()
        (gap,) = rec.of(ev.SequenceGap)
        assert gap.expected == dropped[0]
        assert rec.of(ev.FullStateRequested) == [ev.FullStateRequested()]
        assert any(f.op == 0x30 for f in proxy.seen_down)  # REQUEST_ALL on the wire

    run(main())


def test_silent_link_goes_down_and_the_ixl_reconnects() -> None:
    async def main() -> None:
        cfg = Type2Config(heartbeat_period=0.05, t_max=0.25, ident_timeout=0.5, nak_repeat=0.05)
        rec = Recorder()
        tables = IndicationTables([20])
        async with CtcServer([20], tables, config=cfg, on_event=rec) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table(50)
            async with IxlClient(20, "127.0.0.1", port, app, config=cfg, on_event=rec, **FAST) as c:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                # idle but alive: heartbeats both ways keep it up. Wait for the heartbeats of
                # twice T_MAX of idle time, each way (every timer runs on this one loop, so a
                # T_MAX that heartbeats did not hold off would have fired before the last of them)
                loop = asyncio.get_running_loop()
                start, up, down = loop.time(), len(proxy.seen_up), len(proxy.seen_down)
                beats = round(2 * cfg.t_max / cfg.heartbeat_period) + 1

                def idle_span_seen() -> bool:
                    return (
                        sum(f.op == HEARTBEAT for f in proxy.seen_up[up:]) >= beats
                        and sum(f.op == HEARTBEAT for f in proxy.seen_down[down:]) >= beats
                        and loop.time() - start >= 2 * cfg.t_max
                    )

                await poll_until(idle_span_seen)
                assert c.connections == 1 and not rec.of(ev.LinkDown)
                proxy.frozen = True
                await ctc.wait_until(lambda: len(rec.of(ev.LinkDown)) >= 2)
                proxy.frozen = False
                changes = change(app, c, [1, 2])  # dropped while down; the full state has them
                assert changes
                await ctc.wait_until(
                    lambda: (
                        c.connections >= 2
                        and tables.stations[20].synced
                        and tables.stations[20].state == app.state
                    )
                )
            await proxy.close()

    run(main())


def test_cutting_tcp_mid_frame_ends_in_a_full_resync() -> None:
    async def main() -> None:
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            proxy = Proxy(ctc.port)
            port = await proxy.start()
            app = table(1000)
            cut: list[int] = []

            def up(f):
                if f.op == INDICATION and f.sub == 0 and not cut:
                    cut.append(f.seq)
                    return CUT
                return f.raw

            proxy.up = up
            async with IxlClient(20, "127.0.0.1", port, app, **FAST) as c:
                await ctc.wait_until(lambda: tables.stations[20].synced)
                change(app, c, list(range(1, 41)))  # this frame is cut in half
                await ctc.wait_until(lambda: not tables.stations[20].connected)
                for k in range(41, 200, 7):  # the IXL keeps changing while the link is down
                    app.state[k] = (app.state[k] + 1) % 4
                await ctc.wait_until(
                    lambda: (
                        c.connections >= 2
                        and tables.stations[20].synced
                        and tables.stations[20].state == app.state
                    )
                )
            await proxy.close()
        assert cut

    run(main())


def test_peer_sending_repeated_bad_frames_is_dropped(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        from ktcs_bench.codec import FrameCodec

        codec = FrameCodec(PROFILE)
        policy = AdmissionPolicy([20], bad_frame_limit=3)
        tables = IndicationTables(policy.stations)
        async with CtcServer(policy, tables) as ctc:
            reader, writer = await asyncio.open_connection("127.0.0.1", ctc.port)
            writer.write(codec.encode_message(0, "IDENT", 0, station=20, version=1))
            await ctc.wait_until(lambda: tables.stations[20].connected)
            # damaged frames without a stray STX inside (so each decodes as one error frame)
            bad = [damage(codec.encode_message(seq, "HEARTBEAT", 0)) for seq in range(16, 64)]
            for frame in [b for b in bad if 0x02 not in b[1:]][:3]:
                writer.write(frame)
                await writer.drain()
            await ctc.wait_until(lambda: not tables.stations[20].connected)
            assert await reader.read() != b""  # IDENT accepted, NAKs, then EOF
            writer.close()
            assert any(reason.startswith("dropped") for _, reason in ctc.refusals)

    with caplog.at_level(logging.WARNING, logger="ktcs_bench.type2"):
        run(main())
    assert any(
        "dropped" in r.getMessage() and "127.0.0.1:" in r.getMessage() for r in caplog.records
    )


def test_server_listens_on_loopback_by_default() -> None:
    async def main() -> None:
        tables = IndicationTables([20])
        async with CtcServer([20], tables) as ctc:
            assert ctc.host == "127.0.0.1"
            assert ctc._server is not None
            assert {s.getsockname()[0] for s in ctc._server.sockets} == {"127.0.0.1"}

    run(main())
