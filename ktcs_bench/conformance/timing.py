"""The safety timings the suite judges a device by, named as a signalling engineer names them.

Type I (SPEC §3.4): ΔR (frame timeout), ACK timeout, link-test period, T_MAX (silence before the
link is down; RaSTA's name), retry count. Type II (SPEC §4): heartbeat period, T_MAX, retry count.
Defaults come from the framing profile and the line (`LinkConfig.resolve`, `Type2Config`); every
value can be overridden from the command line. `tolerance` is how late a timer may fire before the
suite calls it wrong -- generous, because a loaded CI machine delays timers (never advances them).
"""

from __future__ import annotations

from dataclasses import dataclass

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.type1.config import LINE_RATE, LinkConfig
from ktcs_bench.type2.config import Type2Config

# The reference lab's Type I links carry at most a 132-code ALL_INFO (emulators/labs/reference.yaml).
DEFAULT_LONGEST_FRAME = 132
# A timer firing this much after its nominal time is still a pass (scheduling on a busy machine).
DEFAULT_TOLERANCE = 0.75
# A timer may fire this fraction of its nominal time early (clock granularity, measurement skew).
EARLY_FRACTION = 0.8


@dataclass(frozen=True, slots=True)
class SuiteTiming:
    """Resolved timings in seconds. `line_rate` None means an unpaced line (a pty at full speed)."""

    line_rate: float | None
    delta_r: float
    ack_timeout: float
    link_test_period: float
    t_max: float
    retry_count: int
    heartbeat_period: float
    t2_t_max: float
    tolerance: float = DEFAULT_TOLERANCE

    @classmethod
    def resolve(
        cls,
        profile: FrameProfile,
        *,
        line_rate: float | None = LINE_RATE,
        longest_frame: int | None = None,
        delta_r: float | None = None,
        ack_timeout: float | None = None,
        heartbeat_period: float | None = None,
        t_max: float | None = None,
        retry_count: int | None = None,
        tolerance: float = DEFAULT_TOLERANCE,
    ) -> SuiteTiming:
        """Defaults from SPEC §3.4 / §4 for this profile and line, each overridable."""
        t2 = Type2Config()
        if profile.protocol == "type1":
            longest = DEFAULT_LONGEST_FRAME if longest_frame is None else longest_frame
            cfg = LinkConfig(
                line_rate=line_rate or None,
                longest_frame_data=min(longest, profile.max_data),
                delta_r=delta_r,
                ack_timeout=ack_timeout,
                link_test_period=heartbeat_period or 1.0,
                link_down_after=t_max,
                max_retransmissions=3 if retry_count is None else retry_count,
            )
            timers = cfg.resolve(profile)
            return cls(
                line_rate=line_rate or None,
                delta_r=timers.delta_r,
                ack_timeout=timers.ack_timeout,
                link_test_period=timers.link_test_period,
                t_max=timers.link_down_after,
                retry_count=timers.max_transmissions - 1,
                heartbeat_period=timers.link_test_period,
                t2_t_max=t2.t_max,
                tolerance=tolerance,
            )
        hb = heartbeat_period or t2.heartbeat_period
        return cls(
            line_rate=None,
            delta_r=0.0,
            ack_timeout=0.0,
            link_test_period=hb,
            t_max=t_max or t2.t_max,
            retry_count=t2.retry_count if retry_count is None else retry_count,
            heartbeat_period=hb,
            t2_t_max=t_max or t2.t_max,
            tolerance=tolerance,
        )

    @property
    def byte_time(self) -> float:
        return 10 / self.line_rate if self.line_rate else 0.0

    def wire_time(self, n_bytes: int) -> float:
        return n_bytes * self.byte_time

    def within(self, measured: float, nominal: float) -> bool:
        """A timer that fired `measured` s after it started, nominally `nominal` s."""
        return EARLY_FRACTION * nominal - 0.005 <= measured <= nominal + self.tolerance

    def describe(self) -> dict[str, float | int | None]:
        return {
            "line_rate": self.line_rate,
            "delta_r": round(self.delta_r, 4),
            "ack_timeout": round(self.ack_timeout, 4),
            "link_test_period": self.link_test_period,
            "t_max": self.t_max,
            "retry_count": self.retry_count,
            "heartbeat_period": self.heartbeat_period,
            "tolerance": self.tolerance,
        }
