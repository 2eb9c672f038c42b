"""Type I link timers and limits (SPEC §3.4), named as a signalling engineer names them.

Owns: `LinkConfig` (what a lab file or a test sets per link) and `LinkTimers` (the resolved numbers
the link runs on). Defaults are computed from the line rate and the longest frame the link carries:

* wire time of N bytes = N × bits_per_byte / line_rate (9600 bit/s 8N1: 1.042 ms a byte);
* ΔR (frame timeout: STX seen, frame not complete) = 1.5 × wire time of the longest frame + 20 ms;
* ACK timeout = ΔR + wire time of an ACK frame + 50 ms, counted from the end of our frame on the wire;
* link test period 1 s (a LINK_TEST when our direction has sent nothing for that long);
* link down after 3 link-test periods with no valid frame received;
* communication error after 3 retransmissions (4 transmissions) without ACK.

Must not touch: clocks, sockets. Pure arithmetic on a profile.
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.codec import FrameProfile
from ktcs_bench.errors import UsageError

LINE_RATE = 9600.0  # bit/s, seed 004 §3.1 (RS485)
BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit
DELTA_R_FACTOR = 1.5  # ΔR = 1.5 × longest frame + margin (SPEC §3.4)
DELTA_R_MARGIN = 0.020  # s
ACK_MARGIN = 0.050  # s, added to ΔR + ACK wire time for the peer's turnaround
LINK_TEST_PERIOD = 1.0  # s
LINK_DOWN_PERIODS = 3  # link-test periods of silence before the link is declared down
MAX_RETRANSMISSIONS = 3  # then communication error (4 transmissions in all)


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Per-link settings; any `None` takes the SPEC §3.4 default computed from the others.

    line_rate: bit/s on the wire (None or 0: unpaced, wire times count as 0).
    bits_per_byte: 10 for 8N1.
    longest_frame_data: DATA bytes of the longest frame this link carries (default: the
        profile's maximum, 1024 in `ktcs-type1`); a 132-code ALL_INFO link can say 132.
    delta_r: ΔR, the frame timeout in seconds.
    ack_timeout: seconds from the end of our data frame on the wire to giving up on its ACK.
    link_test_period: seconds of transmit silence before a LINK_TEST.
    link_down_after: seconds with no valid frame received before the link is down.
    max_retransmissions: retransmissions of one frame before communication error.
    """

    line_rate: float | None = LINE_RATE
    bits_per_byte: int = BITS_PER_BYTE
    longest_frame_data: int | None = None
    delta_r: float | None = None
    ack_timeout: float | None = None
    link_test_period: float = LINK_TEST_PERIOD
    link_down_after: float | None = None
    max_retransmissions: int = MAX_RETRANSMISSIONS

    def resolve(self, profile: FrameProfile) -> LinkTimers:
        if self.line_rate is not None and self.line_rate < 0:
            raise UsageError(f"line_rate must be positive, got {self.line_rate}")
        if self.max_retransmissions < 0:
            raise UsageError("max_retransmissions must be 0 or more")
        if self.link_test_period <= 0:
            raise UsageError("link_test_period must be positive")
        byte_time = self.bits_per_byte / self.line_rate if self.line_rate else 0.0
        longest = profile.max_data if self.longest_frame_data is None else self.longest_frame_data
        if not 0 <= longest <= profile.max_data:
            raise UsageError(f"longest_frame_data {longest} outside 0..{profile.max_data}")
        longest_wire = profile.frame_size(longest) * byte_time
        ack_wire = profile.frame_size(0) * byte_time
        delta_r = (
            DELTA_R_FACTOR * longest_wire + DELTA_R_MARGIN if self.delta_r is None else self.delta_r
        )
        ack_timeout = (
            delta_r + ack_wire + ACK_MARGIN if self.ack_timeout is None else self.ack_timeout
        )
        down = (
            LINK_DOWN_PERIODS * self.link_test_period
            if self.link_down_after is None
            else self.link_down_after
        )
        return LinkTimers(
            byte_time=byte_time,
            delta_r=delta_r,
            ack_timeout=ack_timeout,
            link_test_period=self.link_test_period,
            link_down_after=down,
            max_transmissions=self.max_retransmissions + 1,
            longest_frame_wire=longest_wire,
        )


@dataclass(frozen=True, slots=True)
class LinkTimers:
    """The resolved numbers (seconds) a `Type1Link` runs on."""

    byte_time: float
    delta_r: float
    ack_timeout: float
    link_test_period: float
    link_down_after: float
    max_transmissions: int
    longest_frame_wire: float

    def wire_time(self, n_bytes: int) -> float:
        return n_bytes * self.byte_time

    @property
    def retry_span(self) -> float:
        """Longest time a peer may still retransmit a frame after we first accepted it."""
        return self.max_transmissions * (self.ack_timeout + self.longest_frame_wire) + self.delta_r
