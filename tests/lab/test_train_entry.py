"""A timetable train comes onto the line only when its entry track is clear as the rails report it
(issue 23 §2): with ARS off at station 18, train 1001 stands at home signal 01 on TC1851, and
train 1003, due there at 120 s, waits -- off the line, saying so once -- until 1001 has moved on."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from ktcs_bench.emulator.train import train_line
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.station import load_line
from ktcs_bench.train.dynamics import TrainParams
from ktcs_bench.train.endpoint import CYCLE, TrainConfig, TrainEndpoint
from ktcs_bench.train.entry import EntryGate, body_track_circuits

from .conftest import lab_file

LINE = load_line()
ENTRY = next(t for t in LINE.all_track_circuits() if t.name == "TC1851")


async def until(
    lab: InProcessLab, what: str, check: Callable[[], Awaitable[Any]], within: float
) -> Any:
    """Run the lab's clock on in steps of 0.5 s until `check` gives something true."""
    end = lab.now() + within
    while not (value := await check()):
        assert lab.now() < end, f"{what}: not within {within} s of the lab's clock"
        await lab.sleep(0.5)
    return value


async def status(lab: InProcessLab, device: str) -> dict[str, Any]:
    answer = await lab.device(device, {"cmd": "status"})
    assert answer["ok"], answer
    return dict(answer["status"])


def test_a_timetable_train_waits_off_the_line_until_its_entry_track_is_clear(
    tmp_path: Path,
) -> None:
    path = lab_file(tmp_path, "entry", trains=True)
    text = path.read_text(encoding="utf-8").replace("ars: {}", "ars: {start_on: [20, 22]}")
    path.write_text(text, encoding="utf-8")
    lab = InProcessLab(path, invariants=True)
    seen: dict[str, Any] = {}

    async def main(lab: InProcessLab) -> None:
        async def standing() -> bool:
            s = await status(lab, "train1001")
            return s["state"] != "waiting" and s["speed_kmh"] == 0 and s["head"] > 400

        await until(lab, "1001 standing at home signal 01", standing, 60)
        assert "TC1851" in (await status(lab, "tc"))["occupied"]

        async def waiting() -> list[str]:
            return list((await status(lab, "train1003"))["waiting_for"])

        assert await until(lab, "1003 waiting for its entry", waiting, 130) == ["TC1851"]
        assert lab.now() >= 120.0 - 1e-6
        rails = await status(lab, "tc")
        assert "1003" not in rails["trains"] and "TC1851" in rails["occupied"], rails
        assert (await status(lab, "train1003"))["state"] == "waiting"

        on = await lab.device("ctc", {"cmd": "ars", "station": 18, "on": True})
        assert on["ok"], on

        async def on_the_line() -> dict[str, Any] | None:
            rails = await status(lab, "tc")
            if "1003" in rails["trains"]:
                return rails
            seen["clear_at"] = seen.get("clear_at") or (
                None if "TC1851" in rails["occupied"] else lab.now()
            )
            return None

        rails = await until(lab, "1003 on the line", on_the_line, 300)
        head, tail, _ = rails["trains"]["1003"]
        assert (head, tail) == (ENTRY.to_m - 50.0, ENTRY.to_m - 250.0), rails["trains"]
        first_1001 = rails["trains"]["1001"]
        assert min(first_1001[:2]) >= ENTRY.to_m, first_1001  # 1001 left TC1851 behind
        events = (await lab.device("train1003", {"cmd": "events", "last": 200}))["events"]
        seen["entry"] = [(e["time"], e["text"]) for e in events if e["kind"] == "entry"]
        seen["occupancy"] = [
            (e["time"], e["text"])
            for e in (await lab.device("tc", {"cmd": "events", "last": 200}))["events"]
            if "TC1851=0" in e["text"]
        ]

    lab.run(main)
    (waited_at, waited), (entered_at, entered) = seen["entry"]
    assert waited == "waiting for TC1851 clear to enter" and 120.0 - 1e-6 <= waited_at < 121.0
    assert entered == "entered"
    cleared_at = seen["occupancy"][-1][0]  # 1001's tail left TC1851: the rails reported it clear
    assert cleared_at <= entered_at < cleared_at + 2 * CYCLE, (seen, entered_at)
    assert lab.violations() == [], lab.violations()  # nobody on top of anybody


def test_the_gate_holds_the_first_cycle_until_the_rails_report_the_entry_clear() -> None:
    """The gate alone, sans-I/O: due at 5 s, its entry occupied -- no deadline, one waiting
    event -- then clear: the endpoint's first cycle runs at the moment it is told."""
    start = ENTRY.to_m - 50.0
    cfg = TrainConfig(train_id="9", params=TrainParams(length=200.0), start=start, mode="ktcs")
    tcs = body_track_circuits(LINE.all_track_circuits(), start, 200.0, "1")
    assert tcs == ("TC1851",)
    gate = EntryGate(TrainEndpoint(cfg, train_line(LINE), first=5.0), 5.0, tcs)
    assert gate.next_deadline() == 5.0 and gate.handle_timer(4.0) is None
    assert gate.handle_timer(5.0) is None and gate.blocking() == ["TC1851"]  # nothing known yet
    gate.rails({"TC1851": True, "TC1853A": False}, full=True)
    assert gate.next_deadline() is None and gate.handle_timer(7.0) is None
    gate.rails({"TC1853A": True}, full=False)
    assert gate.next_deadline() is None
    assert [e.text for e in gate.take_events()] == ["waiting for TC1851 clear to enter"]
    gate.rails({"TC1851": False}, full=False)
    assert gate.next_deadline() == 5.0  # due: at once
    out = gate.handle_timer(9.3)
    assert out is not None and gate.entered_at == 9.3 and gate.endpoint.cycles == 1
    assert [e.text for e in gate.take_events()] == ["entered"]
    assert gate.next_deadline() == 9.3 + gate.endpoint.cycle
    gate.rails_lost()  # once on the line, the gate holds nothing back
    assert gate.handle_timer(9.3 + gate.endpoint.cycle) is not None


REPORTS = st.lists(
    st.one_of(
        st.tuples(st.just("rails"), st.dictionaries(st.sampled_from(["TC1851", "TC1853A"]),
                                                    st.booleans()), st.booleans()),
        st.tuples(st.just("lost"), st.just({}), st.just(False)),
        st.tuples(st.just("time"), st.just({}), st.just(False)),
    ),
    max_size=30,
)  # fmt: skip


@given(REPORTS, st.floats(0.1, 5.0))
def test_the_gate_never_lets_a_train_on_while_its_entry_is_not_reported_clear(
    reports: list[tuple[str, dict[str, bool], bool]], at_s: float
) -> None:
    """Whatever the rails report, in whatever order (a connection lost, changes before a full
    report): the train comes on only when it is due and every track circuit of its entry is
    known clear, as soon as it is asked then; it says it waits at most once, before it enters."""
    start = ENTRY.to_m - 50.0
    cfg = TrainConfig(train_id="9", params=TrainParams(length=200.0), start=start, mode="ktcs")
    gate = EntryGate(TrainEndpoint(cfg, train_line(LINE), first=at_s), at_s, ("TC1851",))
    known: dict[str, bool] | None = None  # the model: what the rails said, since the last full
    now = 0.0
    for what, occupancy, full in reports:
        if what == "rails":
            gate.rails(occupancy, full)
            known = dict(occupancy) if full else (None if known is None else known | occupancy)
        elif what == "lost":
            gate.rails_lost()
            known = None
        else:
            now += 1.0
            was = gate.entered
            clear = known is not None and known.get("TC1851") is False
            gate.handle_timer(now)
            if not was:
                assert gate.entered == (now >= at_s and clear), (now, known)
    texts = [e.text for e in gate.take_events()]
    assert texts in ([], ["entered"], ["waiting for TC1851 clear to enter"],
                     ["waiting for TC1851 clear to enter", "entered"]), texts  # fmt: skip
