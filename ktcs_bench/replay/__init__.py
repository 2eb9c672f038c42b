"""Replaying a capture into a link (python-can's player shape): the library behind
`ktcs-bench replay`.

Owns: the replay targets (a pty, a pyserial URL or a TCP address as a byte stream both ways, or a
running tap whose frames are injected as if one end sent them; `targets`), and the replay itself --
pacing by the capture's gaps, the line rate or step by step, collecting the replies, comparing them
with an expected capture (`player`). Threads, sockets and serial ports live here; printing and
arguments are the CLI's. Must not import: `cli`, `lab`, `emulator`, `console`.
"""

from ktcs_bench.replay.player import (
    Replay,
    capture_profile,
    compare,
    expected_replies,
    first_difference,
    frames_of,
)
from ktcs_bench.replay.targets import ReplayTarget, StreamTarget, TapTarget, is_tap

__all__ = [
    "Replay",
    "ReplayTarget",
    "StreamTarget",
    "TapTarget",
    "capture_profile",
    "compare",
    "expected_replies",
    "first_difference",
    "frames_of",
    "is_tap",
]
