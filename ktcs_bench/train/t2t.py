"""Train-to-train messages (seed 000 §3.3 i–iv): who is ahead, where its rear is, how fast.

Owns the message a train publishes each cycle and how a follower turns the latest one from its
leader into a target point: the leader's min-safe rear minus the safety distance. A stale message
keeps its last rear (the leader can only have moved forward, so that stays safe).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class T2TMessage:
    train_id: str
    head: float
    tail: float
    """Min-safe rear of the sender, m."""
    speed: float
    time: float


def leader_of(me: str, my_head: float, messages: Sequence[T2TMessage]) -> T2TMessage | None:
    """The nearest train whose rear is ahead of my head (the first such on a tie)."""
    best: T2TMessage | None = None
    limit = my_head - 1e-6
    for m in messages:
        if m.tail > limit and m.train_id != me and (best is None or m.tail < best.tail):
            best = m
    return best


def target_from_leader(msg: T2TMessage, safety_distance: float) -> float:
    return msg.tail - safety_distance
