"""Seed 003 Table 3: the single-step profile, its SI pitfall, and agreement with our EBD."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ktcs_bench.train.curves import FixedValues, Target, TargetKind, ebd_distance
from ktcs_bench.train.deceleration import SafeDeceleration, StepFunction
from ktcs_bench.train.profile import D_EB, V_I_EB, table3_profile
from ktcs_bench.train.units import kmh


def test_profile_is_capped_at_mrsp_plus_vi_and_drops_before_each_decrease() -> None:
    p = table3_profile()
    assert len(p.x) == int(950 / 2.5) + 1
    at = lambda x: int(round(x / 2.5))  # noqa: E731
    assert p.v_eb[at(0.0)] * 3.6 == pytest.approx(97.5)
    assert np.all(p.v_fsb <= p.mrsp + kmh(5.0) + 1e-9)
    assert np.all(p.v_eb <= p.mrsp + kmh(7.5) + 1e-9)
    # at the 90→60 step (240 m) the EB profile has come down to 60 + 7.5 km/h
    assert p.v_eb[at(240.0) - 1] * 3.6 == pytest.approx(
        math.sqrt(2 * D_EB * 2.5 + (kmh(67.5)) ** 2) * 3.6
    )


def test_minimum_over_every_target_not_only_the_next() -> None:
    p = table3_profile()
    # in section 1 (90) the 30 km/h section two steps ahead already limits the EB profile
    i = int(round(230.0 / 2.5))
    to30 = math.sqrt(2 * D_EB * (400.0 - 230.0) + (kmh(30.0) + V_I_EB) ** 2)
    to60 = math.sqrt(2 * D_EB * (240.0 - 230.0) + (kmh(60.0) + V_I_EB) ** 2)
    assert p.v_eb[i] == pytest.approx(min(to30, to60))
    assert np.all(p.v_eb >= p.v_fsb)


def test_single_step_form_equals_our_ebd_to_a_speed_target() -> None:
    d = SafeDeceleration(StepFunction.constant(D_EB))
    t = Target(400.0, kmh(30.0), TargetKind.SPEED)
    for v in (kmh(50.0), kmh(70.0)):
        dist = ebd_distance(d, t, v, FixedValues())
        assert math.sqrt(2 * D_EB * dist + (kmh(30.0) + V_I_EB) ** 2) == pytest.approx(v)
