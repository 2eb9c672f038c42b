"""Issue 16, a real device in the lab: a lab-file entry marked `external` is not started; `lab up`
links it through its link's tap -- the tap opens its serial line (Type I), connects to it (a CTC)
or serves the address it connects to (an IXL). Here independently started emulator processes
stand in for the real devices, each reached only at the endpoint the lab file gives."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ktcs_bench.datafiles import data_dir
from ktcs_bench.errors import ConfigError
from ktcs_bench.lab.topology import load_lab
from ktcs_bench.runtime import private_dir, read_token

from .conftest import RunningLab, request, start_lab, stop_group, wait_until

LINE = (data_dir("emulators") / "lines" / "reference.yaml").resolve()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def write_lab(tmp: Path, name: str, devices: str, links: str) -> Path:
    """A lab file of the given devices and links on the reference line (no web console)."""
    path = tmp / f"{name}.yaml"
    path.write_text(
        f"lab: {name}\nline: {LINE}\ndevices:\n{devices}links:\n{links}", encoding="utf-8"
    )
    return path


def lab_token(run_dir: Path, name: str) -> Path:
    """Where lab `name` keeps its token: a stand-in started before the lab makes it there (mode
    0600) and the lab takes it, so the stand-in's rails and control port share the lab's."""
    return private_dir(run_dir / "labs" / name) / "token"


@contextlib.contextmanager
def stand_in(run_dir: Path, *args: str) -> Iterator[dict[str, Any]]:
    """`ktcs-bench emulator ARGS` started on its own, as a real device would be; its ready line.
    Stopped (its whole process group) on the way out, however the test ends."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "ktcs_bench.cli.main", "emulator", *args],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
        env={**os.environ, "KTCS_BENCH_RUN_DIR": str(run_dir)},
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line, f"the stand-in {args[0]} did not start"
        ready = json.loads(line)
        ready["proc"] = proc
        yield ready
    finally:
        stop_group(proc, 10)
        if proc.stdout is not None:
            proc.stdout.close()


def external_status(lab: RunningLab, name: str) -> dict[str, Any]:
    return lab.lab({"cmd": "status"})["status"]["devices"][name]  # type: ignore[no-any-return]


def test_a_real_atc_on_a_serial_line_is_linked_through_its_tap(tmp_path: Path) -> None:
    name, run_dir, rails = "extatc", tmp_path / "run", free_port()
    token = lab_token(run_dir, name)
    with stand_in(run_dir, "atc", "--station", "18", "--name", "atc18", "--link", "ixl=pty",
                  "--link", f"rails=tcp://127.0.0.1:{rails}", "--token-file", str(token)) as atc:  # fmt: skip
        serial_line = atc["ptys"]["ixl"]  # the "real" ATC's serial port, as the lab sees it
        path = write_lab(
            tmp_path, name,
            "  ctc:   {kind: ctc}\n"
            f"  tc:    {{kind: trackcircuit, port: {rails}}}\n"
            "  ixl18: {kind: ixl, station: 18}\n"
            f"  atc18: {{kind: atc, station: 18, external: {{serial: '{serial_line}', rails: true}}}}\n"
            "  io18:  {kind: trackside, station: 18}\n",
            "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
            "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n"
            "  - {name: st18-io,  type: type1, a: ixl18, b: io18}\n",
        )  # fmt: skip
        with start_lab(tmp_path, name, path=path) as lab:
            # the lab runs everything but the ATC, and its tap's ATC end is the ATC's own line
            assert "atc18" not in lab.state()["devices"]
            link = lab.links["st18-atc"]
            assert link["b_end"] == serial_line and link["external"] == ["atc18"], link
            wait_until(
                "ixl18's ATC link up through the tap", lambda: lab.status("ixl18")["links"]["atc"]
            )
            wait_until("the lab reports atc18 external and alive",
                       lambda: external_status(lab, "atc18")["alive"])  # fmt: skip
            assert external_status(lab, "atc18")["external"] == serial_line
            # and so do the commands an operator reads
            status = lab.cli("lab", "status", name)
            assert f"atc18 external at {serial_line}: link up" in status.stdout, status
            assert "external: atc18" in lab.cli("lab", "map", name).stdout

            def atc_codes() -> dict[str, Any]:
                answer = request(atc["control"], {"cmd": "status"}, token=read_token(token))
                return answer["status"]["codes"]  # type: ignore[no-any-return]

            wait_until("the stand-in on the lab's rails", lambda: request(
                atc["control"], {"cmd": "status"}, token=read_token(token))["status"]["rails"])  # fmt: skip
            stop = atc_codes()["TC1853A"][1]
            wait_until("point 31 detected normal at the CTC (the trackside reported it)",
                       lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["points"]["31"] == "normal")  # fmt: skip
            route = lab.ctc({"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "11"})  # fmt: skip
            assert route["ok"] and route["result"] == "accepted", route
            wait_until("signal 01 clears at the CTC",
                       lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["signals"]["01"] != "R")  # fmt: skip
            # the route reached the real ATC over its serial line: its code steps up from stop
            wait_until(
                "the ATC's code on TC1853A steps up", lambda: atc_codes()["TC1853A"][1] > stop
            )
            # the frames passed the tap both ways, recorded in the link's capture
            capture = Path(link["capture"])
            wait_until("both directions in the capture",
                       lambda: {"ixl18>atc18", "atc18>ixl18"} <= set(capture.read_text().split()))  # fmt: skip
            # the lab does not run it, so it cannot restart or kill it, and says so
            for cmd in ("restart", "kill"):
                answer = lab.lab({"cmd": cmd, "device": "atc18"})
                assert not answer["ok"] and "atc18 is external" in answer["error"], answer
            cli = lab.cli("lab", "restart", "atc18", "--lab", name)
            assert cli.returncode == 2 and "external" in cli.stderr, cli
            # the real ATC goes away: it is reported dead, and the IXL puts the signal to stop
            os.killpg(atc["proc"].pid, signal.SIGKILL)
            wait_until("atc18 reported not alive",
                       lambda: not external_status(lab, "atc18")["alive"])  # fmt: skip
            wait_until("signal 01 back to stop at the CTC",
                       lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["signals"]["01"] == "R")  # fmt: skip
            status = lab.lab({"cmd": "status"})["status"]
            assert status["devices"]["atc18"]["crashed"] is None  # not ours: not a crash of ours
            assert not status["taps"]["st18-atc"]["external_ends"]["atc18"]["open"]


def test_without_a_tap_our_ixl_opens_the_real_line_itself(tmp_path: Path) -> None:
    name, run_dir = "extuntapped", tmp_path / "run"
    with stand_in(run_dir, "atc", "--station", "18", "--name", "atc18", "--link", "ixl=pty") as atc:
        serial_line = atc["ptys"]["ixl"]
        path = write_lab(
            tmp_path, name,
            "  ctc:   {kind: ctc}\n  tc:    {kind: trackcircuit}\n"
            "  ixl18: {kind: ixl, station: 18}\n  io18:  {kind: trackside, station: 18}\n"
            f"  atc18: {{kind: atc, station: 18, external: {{serial: '{serial_line}'}}}}\n",
            "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
            "  - {name: st18-atc, type: type1, a: ixl18, b: atc18, tap: false}\n"
            "  - {name: st18-io,  type: type1, a: ixl18, b: io18}\n",
        )  # fmt: skip
        # off the rails, the ATC reports every track circuit occupied: the line is not clear
        with start_lab(tmp_path, name, path=path, clear=False) as lab:
            assert "st18-atc" not in lab.lab({"cmd": "status"})["status"]["taps"]
            assert lab.links["st18-atc"]["a_end"] == serial_line
            wait_until(
                "ixl18's ATC link up on the real line", lambda: lab.status("ixl18")["links"]["atc"]
            )
            wait_until("atc18 alive", lambda: external_status(lab, "atc18")["alive"])
            # not given `rails: true`, the real ATC is not on the bench's rails (the stand-in was
            # not told where they are): it reports its track circuits occupied, fail-safe
            assert lab.ctc({"cmd": "show", "station": 18})["summary"]["occupied"]


def test_a_real_ctc_and_a_real_ixl_at_addresses(tmp_path: Path) -> None:
    """Type II both ways: the taps connect to a real CTC at its address, and serve a real IXL the
    address it is set to connect to (here both ends of that link are real)."""
    name, run_dir, ixl22_port = "extctc", tmp_path / "run", free_port()
    token = lab_token(run_dir, name)
    with stand_in(run_dir, "ctc", "--listen", "127.0.0.1:0", "--token-file", str(token)) as ctc:
        path = write_lab(
            tmp_path, name,
            f"  ctc:   {{kind: ctc, external: {{address: '{ctc['listen']}'}}}}\n"
            "  tc:    {kind: trackcircuit}\n"
            "  ixl18: {kind: ixl, station: 18}\n"
            "  atc18: {kind: atc, station: 18}\n"
            "  io18:  {kind: trackside, station: 18}\n"
            f"  ixl22: {{kind: ixl, station: 22, external: {{address: '127.0.0.1:{ixl22_port}'}}}}\n",
            "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
            "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n"
            "  - {name: st18-io,  type: type1, a: ixl18, b: io18}\n"
            "  - {name: st22-ctc, type: type2, a: ixl22, b: ctc}\n",
        )  # fmt: skip

        def station(st: int) -> dict[str, Any]:
            answer = request(
                ctc["control"], {"cmd": "show", "station": st}, token=read_token(token)
            )
            return answer["summary"]  # type: ignore[no-any-return]

        def synced(st: int) -> bool:
            s = station(st)
            return bool(s["link"] == "up" and s["synced"])

        with start_lab(tmp_path, name, path=path, ready=lambda lab: synced(18)) as lab:
            assert {"ctc", "ixl22"}.isdisjoint(lab.state()["devices"])
            assert lab.links["st22-ctc"]["a_end"] == f"tcp://127.0.0.1:{ixl22_port}"
            assert lab.links["st18-ctc"]["b_end"] == f"tcp://{ctc['listen']}"
            assert not external_status(lab, "ixl22")["alive"]  # nobody connected yet
            with stand_in(run_dir, "ixl", "--station", "22", "--name", "ixl22",
                          "--link", f"ctc=tcp://127.0.0.1:{ixl22_port}"):  # fmt: skip
                wait_until("station 22 synced at the real CTC through the tap", lambda: synced(22))
                wait_until("the lab reports ctc and ixl22 external and alive",
                           lambda: all(external_status(lab, d)["alive"] for d in ("ctc", "ixl22")))  # fmt: skip
                assert lab.lab({"cmd": "status"})["status"]["taps"]["st22-ctc"]["connected"]
            wait_until(
                "ixl22 gone: reported not alive", lambda: not external_status(lab, "ixl22")["alive"]
            )
            answer = lab.lab({"cmd": "restart", "device": "ctc"})
            assert not answer["ok"] and "ctc is external" in answer["error"], answer


@pytest.mark.parametrize(
    ("entry", "place", "words"),
    [
        ("{kind: atc, station: 18, external: {address: '1.2.3.4:5'}}", "devices.atc18.external.address",
         "unknown key"),
        ("{kind: atc, station: 18, external: {serial: pty}}", "devices.atc18.external.serial",
         "pyserial URL"),
        ("{kind: atc, station: 18, external: {serial: 'nope://x'}}", "devices.atc18.external.serial",
         "not known"),
        ("{kind: atc, station: 18, external: {serial: 'rfc2217://h:70000'}}",
         "devices.atc18.external.serial", "out of range"),
        ("{kind: atc, station: 18, external: {serial: /dev/ttyS0, rails: yes please}}",
         "devices.atc18.external.rails", "true or false"),
        ("{kind: atc, station: 18, external: {serial: /dev/ttyS0, rails: true}}",
         "devices.atc18.external.rails", "port"),
        ("{kind: atc, station: 18, external: /dev/ttyS0}", "devices.atc18.external", "mapping"),
        ("{kind: atc, station: 18, external: {}}", "devices.atc18.external.serial", "missing key"),
    ],
)  # fmt: skip
def test_a_bad_external_entry_is_one_error_naming_the_key(
    tmp_path: Path, entry: str, place: str, words: str
) -> None:
    path = write_lab(tmp_path, "bad", f"  ixl18: {{kind: ixl, station: 18}}\n  atc18: {entry}\n",
                     "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n")  # fmt: skip
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    assert err.value.file == str(path) and err.value.place == place, str(err.value)
    assert words in err.value.problem, str(err.value)


@pytest.mark.parametrize(
    ("devices", "links", "place", "words"),
    [
        ("  ctc: {kind: ctc, external: {address: '127.0.0.1:0'}}\n", "", "devices.ctc.external.address",
         "out of range"),
        ("  tc: {kind: trackcircuit, external: {address: '127.0.0.1:7'}}\n", "", "devices.tc.external",
         "cannot be external"),
        ("  ixl18: {kind: ixl, station: 18, external: {address: '127.0.0.1:0'}}\n"
         "  atc18: {kind: atc, station: 18}\n", "  - {name: l, type: type1, a: ixl18, b: atc18}\n",
         "links[0].a", "its Type I peers are its own"),
        ("  ixl18: {kind: ixl, station: 18, external: {address: '127.0.0.1:0'}}\n"
         "  ctc: {kind: ctc}\n", "  - {name: l, type: type2, a: ixl18, b: ctc, tap: false}\n",
         "links[0].tap", "tap: true"),
    ],
)  # fmt: skip
def test_external_kinds_and_links_are_checked(
    tmp_path: Path, devices: str, links: str, place: str, words: str
) -> None:
    path = write_lab(tmp_path, "bad", devices, links or "  []\n")
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    assert err.value.place == place and words in err.value.problem, str(err.value)


def test_good_external_entries_load(tmp_path: Path) -> None:
    path = write_lab(
        tmp_path, "good",
        "  ctc: {kind: ctc, external: {address: '10.0.0.5:6000'}}\n"
        "  tc: {kind: trackcircuit, port: 7000}\n"
        "  ixl18: {kind: ixl, station: 18}\n"
        "  atc18: {kind: atc, station: 18, external: {serial: 'rfc2217://10.0.0.2:4000', rails: true}}\n"
        "  ixl22: {kind: ixl, station: 22, external: {address: '0.0.0.0:0'}}\n",
        "  - {name: st18-ctc, type: type2, a: ixl18, b: ctc}\n"
        "  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n"
        "  - {name: st22-ctc, type: type2, a: ixl22, b: ctc}\n",
    )  # fmt: skip
    lab = load_lab(path)
    assert [d.name for d in lab.ours("ixl")] == ["ixl18"] and not lab.ours("ctc")
    atc = lab.devices["atc18"].external
    assert atc is not None and atc.serial == "rfc2217://10.0.0.2:4000" and atc.rails
    assert lab.devices["ctc"].external is not None
    assert lab.devices["ctc"].external.address == ("10.0.0.5", 6000)


def test_a_link_entry_is_declared_a_misspelt_key_refused_with_its_line(tmp_path: Path) -> None:
    """`links:` entries have a declared shape: a key no reader knows (here `tapp`) is refused,
    not silently ignored, naming the key path and its line."""
    path = write_lab(tmp_path, "misspelt", "  ixl18: {kind: ixl, station: 18}\n  atc18: {kind: atc, station: 18}\n",
                     "  - {name: st18-atc, type: type1, a: ixl18, b: atc18,\n     tapp: false}\n")  # fmt: skip
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    line = path.read_text(encoding="utf-8").splitlines().index("     tapp: false}") + 1
    assert err.value.place == "links[0].tapp"
    assert err.value.problem == f"unknown key (line {line})", str(err.value)


@pytest.mark.parametrize(
    ("extra", "place", "problem"),
    [
        ("colour: blue\n", "colour", "unknown key"),
        ("type1: {profile: ktcs-type1, linerate: 9600}\n", "type1.linerate", "unknown key"),
        ("console: {port: 0, origin: []}\n", "console.origin", "unknown key"),
        ("type2: {profile: 5}\n", "type2.profile", "must be a string, not int"),
        ("timetable: [a]\n", "timetable", "must be a string, not list"),
    ],
    ids=["top", "type1", "console", "type2-profile", "timetable"],
)
def test_the_lab_file_top_level_and_sections_are_declared(
    tmp_path: Path, extra: str, place: str, problem: str
) -> None:
    """A key no reader knows at the top of a lab file or in its settings, silently ignored before,
    is refused naming the key path and its line; a value of the wrong type too."""
    path = write_lab(tmp_path, "declared", "  ixl18: {kind: ixl, station: 18}\n", "  []\n")
    path.write_text(path.read_text(encoding="utf-8") + extra, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    line = path.read_text(encoding="utf-8").splitlines().index(extra.strip()) + 1
    assert err.value.place == place, str(err.value)
    assert err.value.problem == f"{problem} (line {line})", str(err.value)


def test_a_device_s_known_keys_are_declared_its_options_free(tmp_path: Path) -> None:
    """kind, station, host and external have their types; the other keys are the kind's options."""
    path = write_lab(tmp_path, "host", "  ixl18: {kind: ixl, station: 18, host: [a]}\n", "  []\n")
    with pytest.raises(ConfigError) as err:
        load_lab(path)
    assert err.value.place == "devices.ixl18.host", str(err.value)
    assert err.value.problem == "must be a string, not list (line 4)", str(err.value)
    good = write_lab(tmp_path, "opts", "  ixl18: {kind: ixl, station: 18, whatever: 3}\n", "  []\n")
    assert load_lab(good).devices["ixl18"].options == {"whatever": 3}
