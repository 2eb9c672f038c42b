"""The traffic-direction words of a procedure (SPEC §6.6): `ctc: direction ST INTERVAL` is the
console's command as a step, a route refusal is matched by the interlocking's reason name
(`refused: direction`, reason 7), and `expect: ctc ST interval IV ...` reads the interval as the
CTC shows it. Each mistake is one message naming the step."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.errors import ConfigError
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.messages import AskDirection
from ktcs_bench.procedure.model import load_procedure
from ktcs_bench.procedure.steps import CtcStep, ExpectStep

HEAD = "id: p\ntitle: t\nsetup: {lab: reference}\nsteps:\n"


def load(tmp_path: Path, steps: str) -> Any:
    path = tmp_path / "p.yaml"
    path.write_text(HEAD + steps, encoding="utf-8")
    return load_procedure(path)


def test_direction_is_a_ctc_step_and_a_refusal_names_its_reason(tmp_path: Path) -> None:
    p = load(tmp_path, "  - ctc: direction 20 1820\n  - ctc: route set 20 21 92\n"
                       "    refused: direction\n")  # fmt: skip
    ask, route = p.steps
    assert isinstance(ask, CtcStep) and ask.command == AskDirection(station=20, interval="1820")
    assert isinstance(route, CtcStep) and route.refused == "direction"


class _Access:
    def __init__(self, answer: dict[str, Any]) -> None:
        self.answer = answer

    async def device(self, name: str, message: object) -> dict[str, Any]:
        return self.answer


class _Ctx:
    def __init__(self, answer: dict[str, Any]) -> None:
        self.access = _Access(answer)

    async def action_done(self) -> None:
        return None


@pytest.mark.parametrize(
    ("answer", "verdict"),
    [
        # the profile names reason 7 ...
        ({"ok": False, "result": "rejected: direction", "reason": 7}, "pass"),
        # ... or prints only its number: the bench's Reason names it
        ({"ok": False, "result": "rejected: reason 7", "reason": int(Reason.DIRECTION)}, "pass"),
        ({"ok": False, "result": "rejected: track occupied", "reason": 3}, "fail"),
        ({"ok": True, "result": "accepted", "reason": 0}, "fail"),
        ({"ok": False, "result": "rejected: reason 99", "reason": 99}, "fail"),
    ],
)
def test_refused_direction_matches_reason_7_whatever_the_profile_prints(
    tmp_path: Path, answer: dict[str, Any], verdict: str
) -> None:
    (step,) = load(tmp_path, "  - ctc: route set 20 21 92\n    refused: direction\n").steps
    outcome = asyncio.run(step.run(_Ctx(answer)))
    assert outcome.verdict == verdict


class _Observer:
    def __init__(self, intervals: dict[str, Any]) -> None:
        self.intervals = intervals

    async def status(self, device: str) -> dict[str, Any]:
        return {"stations": {"20": {"intervals": self.intervals}}}


def test_expect_reads_the_intervals_direction_holder_and_askers(tmp_path: Path) -> None:
    p = load(tmp_path, "  - expect: ctc 20 interval 1820 is down\n"
                       "  - expect: ctc 20 interval 1820 holder is 20\n"
                       "  - expect: ctc 20 interval 2022 asking contains 22\n"
                       "  - expect: ctc 20 interval 2022 is none\n")  # fmt: skip
    seen = _Observer({
        "1820": {"direction": "down", "holder": 20, "asking": []},
        "2022": {"direction": None, "holder": None, "asking": [22]},
    })  # fmt: skip
    for step in p.steps:
        assert isinstance(step, ExpectStep)
        ok, _ = asyncio.run(step.expectation.check(seen))
        assert ok, step.text
    flipped = _Observer({"1820": {"direction": "up", "holder": 18, "asking": [20]}})
    assert not asyncio.run(p.steps[0].expectation.check(flipped))[0]
    assert not asyncio.run(p.steps[1].expectation.check(flipped))[0]


@pytest.mark.parametrize(
    ("steps", "problem"),
    [
        ("  - ctc: direction 18 2022\n", "station 18 has no interval '2022' to ask"),
        ("  - ctc: direction 18 1618\n", "station 18 has no interval '1618' to ask"),
        ("  - ctc: direction 20\n", "cannot read"),
        ("  - expect: ctc 18 interval 2022 is up\n", "station 18 borders no interval '2022'"),
    ],
)
def test_a_bad_direction_step_is_one_message(tmp_path: Path, steps: str, problem: str) -> None:
    with pytest.raises(ConfigError) as err:
        load(tmp_path, steps)
    assert err.value.place.startswith("step 1")
    assert problem in err.value.problem
