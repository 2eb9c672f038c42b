"""Issue 15 part 2: the whole lab in one process on a virtual clock -- the same device objects,
links paced at the line rate on virtual wires, Type II on memory streams, the taps between the
ends -- operated through `LabAccess` as a live lab is."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from functools import partial
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.errors import UsageError
from ktcs_bench.lab import inprocess
from ktcs_bench.lab.access import LabAccess
from ktcs_bench.lab.inprocess import InProcessLab
from ktcs_bench.station.loader import load_line

from .conftest import lab_file

LINE = load_line()
STOP = LINE.most_restrictive_code.code


async def until(
    lab: LabAccess, what: str, check: Callable[[], Awaitable[Any]], within: float = 30.0
) -> Any:
    """Poll `check` every 0.1 s of the lab's clock until it gives something true."""
    end = lab.now() + within
    while True:
        value = await check()
        if value:
            return value
        if lab.now() > end:
            raise AssertionError(f"{what}: not within {within} s of the lab's clock")
        await lab.sleep(0.1)


async def status(lab: LabAccess, device: str) -> dict[str, Any]:
    answer = await lab.device(device, {"cmd": "status"})
    assert answer["ok"], answer
    return dict(answer["status"])


async def summary(lab: LabAccess, st: int) -> dict[str, Any]:
    answer = await lab.device("ctc", {"cmd": "show", "station": st})
    assert answer["ok"], answer
    return dict(answer["summary"])


async def all_up(lab: LabAccess) -> bool:
    for st in (18, 20, 22):
        s = await status(lab, f"ixl{st}")
        if s["mode"] != "center" or not all(s["links"].values()):
            return False
        if "none" in s["points"].values():  # the trackside's first report not in yet
            return False
        view = await summary(lab, st)
        if view["link"] != "up" or not view["synced"]:
            return False
    for name, kind in lab.devices.items():
        if kind in ("atc", "trackside"):
            s = await status(lab, name)
            if not (s["link"] and s["rails"]):
                return False
    return True


@pytest.fixture(scope="module")
def empty_line(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference lab without its timetable trains (nothing sets routes but the test)."""
    return lab_file(tmp_path_factory.mktemp("vlab"), "vlab")


def run(
    main: Callable[[InProcessLab], Awaitable[Any]], lab: str | Path = "reference", **kwargs: Any
) -> Any:
    return InProcessLab(lab, **kwargs).run(main)


def test_the_reference_lab_comes_up_in_center_mode_with_every_link_up(tmp_path: Path) -> None:
    async def main(lab: InProcessLab) -> float:
        await until(lab, "every station in center mode, every link up", lambda: all_up(lab))
        return lab.now()

    t = run(main, out=tmp_path)
    assert 0 < t < 10  # in the lab's clock: the links' start-up, not a wall-clock wait
    events = (tmp_path / "events.jsonl").read_text().splitlines()
    assert any('"text":"atc link up"' in e and '"device":"ixl18"' in e for e in events)
    assert any('"text":"ctc link up"' in e for e in events)
    captures = sorted(p.name for p in (tmp_path / "captures").iterdir())
    assert captures == sorted(f"{lk}.pcapng" for lk in InProcessLab("reference").links)
    summary_json = (tmp_path / "summary.json").read_text()
    assert '"virtual_s"' in summary_json and '"speed_up"' in summary_json


def test_a_route_set_at_the_ctc_clears_the_signal_and_steps_the_atc_codes(
    empty_line: Path,
) -> None:
    async def main(lab: InProcessLab) -> None:
        await until(lab, "lab up", lambda: all_up(lab))
        before = (await status(lab, "atc18"))["codes"]
        answer = await lab.device(
            "ctc", {"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "11"}
        )
        assert answer["ok"] and answer["result"] == "accepted", answer

        async def cleared() -> bool:
            s = await summary(lab, 18)
            return "0111" in s["routes"] and s["signals"]["01"] != "R"

        await until(lab, "signal 01 clears at the CTC", cleared)
        after = await until(
            lab, "ATC codes step",
            lambda: _codes_if(lab, "atc18", lambda c: c != before and c["TC1853A"][1] > 0),
        )  # fmt: skip
        assert after["TC1853A"][0] != STOP

    run(main, empty_line)


def test_the_ctc_command_log_is_stamped_with_the_labs_virtual_time(empty_line: Path) -> None:
    """The desk takes the lab's clock: in a lab in one process the command log's times and
    durations are virtual seconds, not the wall clock's."""

    async def main(lab: InProcessLab) -> None:
        await until(lab, "lab up", lambda: all_up(lab))
        await lab.sleep(7.25)  # the log's time is the lab's, wherever its clock stands
        before = lab.now()
        answer = await lab.device(
            "ctc", {"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "11"}
        )
        after = lab.now()
        assert answer["ok"] and answer["result"] == "accepted", answer
        entries = (await lab.device("ctc", {"cmd": "log"}))["log"]
        assert [e["command"] for e in entries] == ["route set 18 01 11"]
        entry = entries[0]
        assert before <= entry["time"] <= after, (before, entry, after)
        assert 0 <= entry["seconds"] <= after - before

    run(main, empty_line)


async def _codes_if(lab: LabAccess, atc: str, ok: Callable[[dict[str, Any]], bool]) -> Any:
    codes = (await status(lab, atc))["codes"]
    return codes if codes and ok(codes) else None


def test_a_type1_cut_gives_stop_everywhere_and_restore_resyncs(
    tmp_path: Path, empty_line: Path
) -> None:
    async def main(lab: InProcessLab) -> None:
        await until(lab, "lab up", lambda: all_up(lab))
        answer = await lab.device(
            "ctc", {"cmd": "route", "action": "set", "station": 22, "entry": "01", "exit": "11"}
        )
        assert answer["ok"], answer

        async def signal(st: int, want_stop: bool) -> bool:
            return ((await status(lab, f"ixl{st}"))["signals"]["01"] == "R") is want_stop

        await until(lab, "route set, signal clear", lambda: signal(22, False))
        cut = await lab.link("st22-atc", {"cmd": "cut"})
        assert cut == {"ok": True, "command": "cut"}
        await until(lab, "IXL puts signal 01 to stop", lambda: signal(22, True))
        await until(
            lab, "ATC sends the most restrictive code everywhere",
            lambda: _codes_if(lab, "atc22", lambda c: all(v[0] == STOP for v in c.values())),
        )  # fmt: skip
        assert (await lab.link("st22-atc", {"cmd": "status"}))["status"]["cut"] is True
        assert (await lab.link("st22-atc", {"cmd": "restore"}))["ok"]

        async def link_back() -> bool:
            return bool((await status(lab, "ixl22"))["links"]["atc"])

        await until(lab, "the ATC link resyncs", link_back)
        await until(lab, "signal 01 clears again", lambda: signal(22, False))

    run(main, empty_line, out=tmp_path)
    events = (tmp_path / "events.jsonl").read_text()
    assert '"kind":"tap","t":' in events and '"text":"cut"' in events
    # the cut and the restore are a transition each at each end of the link: one event each
    ixl22 = [json.loads(e)["text"] for e in events.splitlines()
             if '"device":"ixl22","kind":"link"' in e and "atc" in e]  # fmt: skip
    assert ixl22 == ["atc link up", "atc link in communication error", "atc link up"], ixl22
    assert events.count('"device":"atc22","kind":"link"') == 3


def test_an_ixl_restarted_in_process_resyncs_and_the_ctc_view_equals_it_again(
    empty_line: Path,
) -> None:
    async def main(lab: InProcessLab) -> None:
        await until(lab, "lab up", lambda: all_up(lab))
        answer = await lab.device(
            "ctc", {"cmd": "route", "action": "set", "station": 20, "entry": "01", "exit": "11"}
        )
        assert answer["ok"], answer
        await until(lab, "route set", lambda: _routes(lab, 20))
        old = lab.objects["ixl20"]
        assert await lab.lab({"cmd": "kill", "device": "ixl20"}) == {"ok": True}
        await until(lab, "CTC sees station 20 down", lambda: _link_is(lab, 20, "down"))
        dead = await lab.device("ixl20", {"cmd": "status"})
        assert not dead["ok"] and "not running" in dead["error"]
        assert await lab.lab({"cmd": "restart", "device": "ixl20"}) == {"ok": True}
        assert lab.objects["ixl20"] is not old  # a fresh object, at the same addresses
        await until(lab, "station 20 back", lambda: _link_is(lab, 20, "up"))
        await until(lab, "CTC view equals the IXL's state", lambda: _ctc_equals_ixl(lab, 20))
        assert (await summary(lab, 20))["routes"] == []  # a restarted IXL has nothing locked
        # a CTC restarted: every station reconnects and its view equals its IXL's again
        assert await lab.lab({"cmd": "restart", "device": "ctc"}) == {"ok": True}
        for st in (18, 20, 22):
            await until(lab, f"station {st} back at the new CTC", partial(_link_is, lab, st, "up"))
            await until(lab, f"CTC view of {st} equals its IXL", partial(_ctc_equals_ixl, lab, st))

    run(main, empty_line)


def test_device_faults_through_the_devices_own_commands(empty_line: Path) -> None:
    async def main(lab: InProcessLab) -> None:
        await until(lab, "lab up", lambda: all_up(lab))
        answer = await lab.device("io20", {"cmd": "fail_point", "point": "31", "kind": "detection"})
        assert answer == {"ok": True}, answer

        async def point(state: str) -> bool:
            return bool((await status(lab, "ixl20"))["points"]["31"] == state)

        await until(lab, "the IXL loses point 31's detection", lambda: point("none"))
        assert (await lab.device("io20", {"cmd": "clear_faults"}))["ok"]
        await until(lab, "detection back", lambda: point("normal"))
        answer = await lab.device("tc", {"cmd": "fail", "tc": "TC2054", "kind": "failed_occupied"})
        assert answer == {"ok": True}, answer

        async def occupied() -> bool:
            return "TC2054" in (await status(lab, "ixl20"))["occupied"]

        await until(lab, "the failed track circuit reads occupied at the IXL", occupied)

    run(main, empty_line)


async def _routes(lab: LabAccess, st: int) -> bool:
    return bool((await summary(lab, st))["routes"])


async def _link_is(lab: LabAccess, st: int, state: str) -> bool:
    s = await summary(lab, st)
    return bool(s["link"] == state and (state == "down" or s["synced"]))


async def _ctc_equals_ixl(lab: LabAccess, st: int) -> bool:
    ctc_state = (await lab.device("ctc", {"cmd": "show", "station": st}))["state"]
    ixl_state = (await status(lab, f"ixl{st}"))["ctc_state"]
    return bool(ctc_state) and list(ctc_state.values()) == [
        ixl_state[k] for k in sorted(ixl_state, key=int)
    ]


def test_bad_input_gets_clear_errors() -> None:
    async def main(lab: InProcessLab) -> None:
        with pytest.raises(UsageError, match="no device 'nope'"):
            await lab.device("nope", {"cmd": "status"})
        with pytest.raises(UsageError, match="no link 'nope'"):
            await lab.link("nope", {"cmd": "cut"})
        bad = await lab.device("ctc", {"cmd": "fly"})
        assert not bad["ok"] and "unknown command 'fly'" in bad["error"]
        bad = await lab.link("st18-atc", {"cmd": "fly"})
        assert not bad["ok"] and "unknown command 'fly'" in bad["error"]
        bad = await lab.lab({"cmd": "restart", "device": "nope"})
        assert not bad["ok"] and "no device 'nope'" in bad["error"]
        bad = await lab.lab({"cmd": "restart"})
        assert not bad["ok"] and "missing" in bad["error"]

    run(main)


def test_a_lab_file_with_tls_is_refused_in_process(tmp_path: Path) -> None:
    from ktcs_bench.lab.topology import default_lab_path

    text = default_lab_path().read_text().replace("profile: ktcs-type2", "profile: type2-tls")
    text = text.replace(": ../", f": {default_lab_path().parent.parent}/")  # line, timetable
    lab_file = tmp_path / "tls.yaml"
    lab_file.write_text(text)
    with pytest.raises(UsageError, match="TLS .* runs in a live lab only"):
        InProcessLab(lab_file)


def _simulate(out: Path, hashseed: str) -> None:
    env = {**os.environ, "PYTHONHASHSEED": hashseed}
    run_ = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "simulate", "reference",
         "--for", "40", "--seed", "7", "--out", str(out)],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert run_.returncode == 0, run_.stderr


def test_same_lab_seed_and_duration_give_byte_identical_events_and_captures(
    tmp_path: Path,
) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    _simulate(a, "1")
    _simulate(b, "2")
    files = sorted(
        p.relative_to(a) for p in a.rglob("*") if p.is_file() and p.name != "summary.json"
    )
    assert Path("events.jsonl") in files and len(files) > 5
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f"{f} differs between two runs"
    assert len((a / "events.jsonl").read_bytes()) > 1000


def test_lab_up_in_process_serves_status_ctc_and_taps_on_real_sockets(
    tmp_path: Path, empty_line: Path
) -> None:
    """`lab up --in-process`: one process, a scaled clock, and the lab answers the same commands
    on real sockets as a live lab (`lab status`, `ctc show`, `tap fault`), and `lab down` ends it."""
    env = {**os.environ, "KTCS_BENCH_RUN_DIR": str(tmp_path / "run")}

    def cli(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", *args],
                              capture_output=True, text=True, env=env, timeout=60)  # fmt: skip

    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(empty_line),
         "--in-process", "--speed", "5", "--json", "--interval", "3600"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        first = json.loads(proc.stdout.readline() or "{}")
        assert first.get("lab") == "vlab" and first.get("console"), first
        deadline = time.monotonic() + 60
        while True:  # the stations come up (the lab's clock runs 5x the wall's)
            run_ = cli("lab", "status", "vlab", "--json")
            assert run_.returncode == 0, run_.stderr
            stations = json.loads(run_.stdout)["stations"]
            if stations and all(s["link"] == "up" and s["synced"] for s in stations.values()):
                break
            assert time.monotonic() < deadline, stations
            time.sleep(0.5)
        run_ = cli("ctc", "--lab", "vlab", "--json", "show", "20")
        assert run_.returncode == 0 and json.loads(run_.stdout)["summary"]["link"] == "up", run_
        run_ = cli("tap", "fault", "st20-atc", "cut")
        assert run_.returncode == 0 and "cut" in run_.stdout, run_.stderr
        run_ = cli("lab", "down", "vlab")
        assert run_.returncode == 0, run_.stderr
        assert proc.wait(30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_periodic_flush_never_reaches_a_capture_the_lab_has_closed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The files are flushed between the loop's steps; while the lab winds down its taps close
    their captures one by one and the loop steps on. With a flush at every step (period 0) a
    flush of a closed capture would end the run with `ValueError: flush of closed file`."""
    monkeypatch.setattr(inprocess, "FLUSH_EVERY", 0.0)

    async def main(lab: InProcessLab) -> None:
        await until(lab, "every station in center mode, every link up", lambda: all_up(lab))

    run(main, out=tmp_path)
    assert (tmp_path / "summary.json").is_file()
    assert all(p.stat().st_size > 0 for p in (tmp_path / "captures").iterdir())
