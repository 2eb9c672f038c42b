"""Issue 22 part 4d: replay is a library call (`ktcs_bench.replay`) with a thin CLI over it: a
capture replayed into a real TCP peer on 127.0.0.1 that answers every request, the replies taken,
seen as they come and compared with an expected capture -- with no CLI in the way."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest

from ktcs_bench.capture import Capture, CaptureRecord
from ktcs_bench.codec import FrameCodec, StreamDecoder, get_profile
from ktcs_bench.replay import Replay, StreamTarget, capture_profile, compare

PROFILE = get_profile("ktcs-type2")
CODEC = FrameCodec(PROFILE)


def request(seq: int) -> bytes:
    return CODEC.encode_message(seq, "REQUEST_ALL", sub=0)


def answer(seq: int) -> bytes:
    return CODEC.encode_message(seq, "HEARTBEAT", sub=0)


@pytest.fixture
def peer() -> Iterator[int]:
    """A TCP peer answering each frame it gets with a HEARTBEAT of the same SEQ."""
    server = socket.create_server(("127.0.0.1", 0))
    done = threading.Event()

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            conn.settimeout(0.1)
            dec = StreamDecoder(PROFILE)
            while not done.is_set():
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                if not data:
                    return
                for frame in dec.feed(data):
                    conn.sendall(answer(frame.seq))  # type: ignore[union-attr]

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[1]
    done.set()
    thread.join(5)
    server.close()


def test_a_replay_sends_paces_and_collects_the_replies_as_a_library_call(peer: int) -> None:
    capture = Capture(
        records=[CaptureRecord(float(k), "ctc>ixl", request(k)) for k in range(3)],
        profile=None,
        link="type2",
        start=None,
    )
    assert capture_profile(capture, None, None, "type2").name == "ktcs-type2"  # by the vote
    target = StreamTarget(f"tcp://127.0.0.1:{peer}", PROFILE, "ixl>ctc", 9600)
    sent: list[CaptureRecord] = []
    seen: list[CaptureRecord] = []
    try:
        replay = Replay(target, capture.records, "ctc>ixl", timing="step", wait=1.0,
                        on_sent=sent.append, on_reply=seen.append, name="peer")  # fmt: skip
        replies = replay.run()
    finally:
        target.close()
    assert [r.data for r in sent] == [request(k) for k in range(3)]
    assert {r.direction for r in sent} == {"ctc>ixl"}
    assert b"".join(r.data for r in replies) == b"".join(answer(k) for k in range(3))
    assert seen == replies and {r.direction for r in replies} == {"ixl>ctc"}
    # the replies against an expected capture: the same, then one that differs in its last SEQ
    want = [CaptureRecord(None, "ixl>ctc", answer(k)) for k in range(3)]
    same = Capture(records=want, profile=None, link="type2", start=None)
    assert compare(same, ("ctc>ixl",), replies, PROFILE) == (3, None)
    other = Capture(records=[*want[:2], CaptureRecord(None, "ixl>ctc", answer(7))],
                    profile=None, link="type2", start=None)  # fmt: skip
    got, diff = compare(other, ("ctc>ixl",), replies, PROFILE)
    assert got == 3 and diff is not None and diff.startswith("reply frame 3 differs")
