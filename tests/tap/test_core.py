"""The tap's core on its own: bytes, commands and a virtual `now` in; deliveries, records, the
event stream and the next deadline out -- no loop, no pty, no socket, no clock."""

from __future__ import annotations

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from ktcs_bench.codec import FrameCodec, get_profile
from ktcs_bench.errors import UsageError
from ktcs_bench.faults import Delay, DropFrame
from ktcs_bench.tap import TapCore
from ktcs_bench.tap.control import Command, parse_command

PROFILE = get_profile("ktcs-type1")
CODEC = FrameCodec(PROFILE)
T = 1000.0


def core(**kw: int) -> TapCore:
    return TapCore(("ixl", "atc"), PROFILE, **kw)


def test_bytes_pass_through_and_each_frame_is_recorded_and_streamed() -> None:
    tap = core()
    sub = tap.subscribe()
    frames = [CODEC.encode(k, 3) for k in range(3)]
    out = tap.receive("ixl>atc", b"".join(frames), T)
    assert out.deliveries == [("ixl>atc", b"".join(frames))]
    assert [(r.time, r.direction, r.data) for r in out.records] == [
        (T, "ixl>atc", f) for f in frames
    ]
    assert (
        sub.take()
        == out.events
        == [{"time": T, "direction": "ixl>atc", "hex": f.hex()} for f in frames]
    )
    assert list(tap.history) == out.records and tap.next_deadline() is None


def test_half_a_frame_is_recorded_as_it_stands_at_the_deadline() -> None:
    tap = core()
    frame = CODEC.encode(1, 3)
    out = tap.receive("atc>ixl", frame[:5], T)
    assert out.deliveries == [("atc>ixl", frame[:5])] and out.records == []
    deadline = tap.next_deadline()
    assert deadline is not None and deadline > T
    assert tap.handle_timer(deadline - 0.01).records == []
    (record,) = tap.handle_timer(deadline).records
    assert record.data == frame[:5] and record.time == T


@example(start=0.145, cut=5)  # 0.145 + 0.2 - 0.145 < 0.2 (the recorder's idle flush)
@example(start=0.037, cut=5)  # 0.037 + 0.25 - 0.037 < 0.25 (the injector's hold timeout)
@given(start=st.floats(0.0, 1e7), cut=st.integers(1, 8))
def test_a_timer_call_at_the_deadline_leaves_no_deadline_at_or_before_it(
    start: float, cut: int
) -> None:
    tap = core()
    tap.execute(parse_command("drop-frame ixl->atc", tap.names), start)  # holds partial frames
    frame = CODEC.encode(1, 3, bytes(range(10)))
    tap.receive("ixl>atc", frame[:cut], start)
    tap.receive("atc>ixl", frame[:cut], start)
    now = start
    for _ in range(4):
        due = tap.next_deadline()
        if due is None:
            break
        now = max(now, due)
        tap.handle_timer(now)
        after = tap.next_deadline()
        assert after is None or after > now, (after, now)


def test_a_fault_command_is_answered_streamed_in_order_and_applied() -> None:
    tap = core()
    sub = tap.subscribe()
    frames = [CODEC.encode(k, 3) for k in range(2)]
    answer, out = tap.execute(parse_command("drop-frame ixl->atc", tap.names), T)
    assert answer == {"ok": True, "command": "drop-frame 1 ixl>atc"}
    assert out.events == [{"time": T, "event": "fault", "command": "drop-frame 1 ixl>atc"}]
    out = tap.receive("ixl>atc", b"".join(frames), T + 1)
    assert out.deliveries == [("ixl>atc", frames[1])]
    events = sub.take()
    assert [e.get("event") or e["hex"] for e in events] == ["fault", frames[1].hex()]
    assert tap.status()["directions"]["ixl>atc"]["stats"]["frames_dropped"] == 1


def test_delay_gives_a_deadline_and_delivers_there() -> None:
    tap = core()
    tap.execute(Command("delay", fault=Delay(0.5)), T)
    assert tap.receive("atc>ixl", b"late", T).deliveries == []
    assert tap.next_deadline() == pytest.approx(T + 0.5)
    assert tap.handle_timer(T + 0.5).deliveries == [("atc>ixl", b"late")]


def test_send_goes_through_the_faults_of_its_direction() -> None:
    tap = core()
    tap.execute(Command("cut", "atc>ixl", parse_command("cut atc>ixl").fault), T)
    answer, out = tap.execute(parse_command("send atc>ixl 0203"), T)
    assert answer["ok"] and out.deliveries == []  # cut: the injected bytes are lost too
    answer, out = tap.execute(parse_command("send ixl>atc 0203"), T)
    assert out.deliveries == [("ixl>atc", b"\x02\x03")]
    assert out.events[0] == {"time": T, "event": "send", "command": "send ixl>atc 0203"}


def test_cut_of_the_whole_link_is_said_so_and_restore_ends_it() -> None:
    tap = core()
    _, out = tap.execute(parse_command("cut ixl>atc"), T)
    assert not out.link_cut and not tap.cut_all
    _, out = tap.execute(parse_command("cut"), T)
    assert out.link_cut and tap.cut_all
    assert tap.receive("ixl>atc", b"x", T).deliveries == []
    tap.execute(parse_command("restore"), T)
    assert not tap.cut_all and tap.receive("ixl>atc", b"x", T).deliveries == [("ixl>atc", b"x")]


def test_a_direction_the_tap_has_not_is_refused() -> None:
    with pytest.raises(UsageError, match="ixl>atc, atc>ixl"):
        core().execute(parse_command("ber 1e-3 a->b"), T)
    with pytest.raises(UsageError):
        core().execute(Command("status"), T)  # not a command that changes the link


def test_a_lost_connection_takes_its_queued_bytes_with_it() -> None:
    tap = core()
    tap.execute(Command("delay", fault=Delay(5.0)), T)
    tap.receive("ixl>atc", b"stale", T)
    out = tap.disconnected(T + 1, "ixl closed")
    assert out.events == [{"time": T + 1, "event": "disconnected", "reason": "ixl closed"}]
    assert tap.handle_timer(T + 10).deliveries == [] and tap.next_deadline() is None


def test_a_new_connection_first_flushes_what_the_recorder_held() -> None:
    tap = core()
    frame = CODEC.encode(1, 3)
    tap.receive("ixl>atc", frame[:4], T)
    out = tap.connected(T + 0.01, ("127.0.0.1", 4000))
    assert [r.data for r in out.records] == [frame[:4]]
    assert out.events[-1] == {"time": T + 0.01, "event": "connected", "peer": ["127.0.0.1", 4000]}


def test_subscribers_get_history_and_a_slow_one_misses_what_overflows() -> None:
    tap = core(history=2)
    for k in range(3):
        tap.receive("ixl>atc", CODEC.encode(k, 3), T)
    late = tap.subscribe(history=True)
    assert [e["hex"] for e in late.take()] == [CODEC.encode(k, 3).hex() for k in (1, 2)]
    slow = tap.subscribe(limit=2)
    for k in range(5):
        tap.receive("ixl>atc", CODEC.encode(k, 3), T)
    assert len(slow.take()) == 2 and slow.missed == 3
    tap.unsubscribe(slow)
    tap.receive("ixl>atc", CODEC.encode(9, 3), T)
    assert slow.take() == [] and len(late.take()) == 6


def test_the_same_seed_gives_the_same_errors() -> None:
    outs = []
    for _ in range(2):
        tap = core(seed=3)
        tap.execute(parse_command("ber 0.01"), T)
        outs.append(tap.receive("ixl>atc", bytes(4000), T).deliveries)
    assert outs[0] == outs[1] and outs[0][0][1] != bytes(4000)
    tap = core(seed=4)
    tap.execute(parse_command("ber 0.01"), T)
    assert tap.receive("ixl>atc", bytes(4000), T).deliveries != outs[0]


def test_frame_fault_json_and_words_mean_the_same() -> None:
    for words in ("drop-frame 2 atc>ixl", "corrupt -5 0x10", "noise 0.001 4", "loss 0.5 both"):
        cmd = parse_command(words)
        assert Command.from_json(cmd.to_json()) == cmd
    assert parse_command("drop-frame 2 atc>ixl").fault == DropFrame(2, direction="atc>ixl")
