"""The safety timings the suite judges a device by, named as a signalling engineer names them.

Type I (SPEC §3.4): ΔR (frame timeout), ACK timeout, link-test period, T_MAX (silence before the
link is down; RaSTA's name), retry count. Type II (SPEC §4): heartbeat period, T_MAX, retry count.
Defaults come from the framing profile and the line (`LinkConfig.resolve`, `Type2Config`); every
value can be overridden from the command line. `tolerance` is how late a timer may fire before the
suite calls it wrong -- generous, because a loaded CI machine delays timers (never advances them).

`MeasuredTiming` is what the device was seen to do: the cases that time a timer write into it, and
`--timings auto` measures it first (`conformance.measure`) and judges the device by it, for a device
whose documentation is missing.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.type1.config import LINE_RATE, LINK_DOWN_PERIODS, LinkConfig
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

    def adopt(self, measured: MeasuredTiming) -> SuiteTiming:
        """These timings with every figure the device was measured at in place of the assumed
        one (a Type I T_MAX that was the default, 3 link-test periods, follows the period)."""
        m = measured
        period = m.link_test_period or self.link_test_period
        derived = abs(self.t_max - LINK_DOWN_PERIODS * self.link_test_period) < 1e-9
        t_max = LINK_DOWN_PERIODS * period if derived else self.t_max
        return dataclasses.replace(
            self,
            delta_r=self.delta_r if m.delta_r is None else m.delta_r,
            ack_timeout=self.ack_timeout if m.ack_timeout is None else m.ack_timeout,
            link_test_period=period,
            t_max=t_max,
            retry_count=self.retry_count if m.retry_count is None else m.retry_count,
            heartbeat_period=m.heartbeat_period or self.heartbeat_period,
            t2_t_max=m.t2_t_max or self.t2_t_max,
        )

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


@dataclass(slots=True)
class MeasuredTiming:
    """The device's timers as measured on the wire (None: not measured in this run).

    delta_r: partial frame sent → its NAK; ack_timeout: a held-back frame's first transmission →
    its retransmission, less the frame's wire time; link_test_period: mean gap between the idle
    device's LINK_TESTs; retry_count: retransmissions before it gave up; heartbeat_period and
    t2_t_max the same for Type II (HEARTBEAT gap; our last frame → the device closing)."""

    delta_r: float | None = None
    ack_timeout: float | None = None
    link_test_period: float | None = None
    retry_count: int | None = None
    heartbeat_period: float | None = None
    t2_t_max: float | None = None

    def describe(self) -> dict[str, float | int | None]:
        return {
            k: (round(v, 4) if isinstance(v, float) else v)
            for k, v in dataclasses.asdict(self).items()
            if v is not None
        }

    def text(self) -> str:
        """One line, as a signalling engineer names them; empty when nothing was measured."""
        parts = []
        for key, name, unit in _NAMES:
            value = getattr(self, key)
            if value is None:
                continue
            shown = {"ms": f"{value * 1000:.0f} ms", "s": f"{value:.2f} s"}.get(unit, str(value))
            parts.append(f"{name} {shown}")
        return ", ".join(parts)


_NAMES = (("delta_r", "ΔR", "ms"), ("ack_timeout", "ACK timeout", "ms"),
          ("link_test_period", "link-test period", "s"), ("retry_count", "retry count", ""),
          ("heartbeat_period", "heartbeat period", "s"), ("t2_t_max", "T_MAX", "s"))  # fmt: skip


def seconds(value: float | None) -> str:
    """A measured time for a note: milliseconds, or "not seen"."""
    return "not seen" if value is None else f"{value * 1000:.0f} ms"


def mean_interval(times: list[float]) -> float | None:
    """The mean gap between successive times (None with fewer than two)."""
    return (times[-1] - times[0]) / (len(times) - 1) if len(times) >= 2 else None
