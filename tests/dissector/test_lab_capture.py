"""Captures from a live lab run (`ktcs-bench lab up`, every device its own process): `monitor
--write` records a Type I link (IXL-ATC, serial over ptys) and a Type II link (IXL-CTC, TCP)
while a route is set from the CTC and the taps inject bit errors and garbage. tshark with the
generated dissector agrees with `ktcs-bench decode --json` on every record of both."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from ktcs_bench.capture import read_capture
from tests.lab.conftest import start_lab, wait_until

from .harness import assert_agree, decoded, dissected, streams, tshark_json

WATCH = 12.0  # seconds each monitor records


def test_captures_of_a_live_lab_run(lua: Path, tmp_path: Path) -> None:
    with start_lab(tmp_path, "dissectorlab") as lab:
        caps = {link: tmp_path / f"{link}.pcapng" for link in ("st18-atc", "st18-ctc")}
        monitors = [
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "ktcs_bench.cli.main",
                    "monitor",
                    link,
                    "--history",
                    "--json",
                    "--write",
                    str(cap),
                    "--timeout",
                    str(WATCH),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
                env={**os.environ, "KTCS_BENCH_RUN_DIR": str(lab.run_dir)},
            )  # fmt: skip
            for link, cap in caps.items()
        ]
        try:
            wait_until("both monitors recording", lambda: all(c.exists() for c in caps.values()))
            assert lab.cli("tap", "fault", "st18-atc", "ber", "3e-3").returncode == 0
            assert lab.cli("tap", "fault", "st18-ctc", "ber", "1e-3").returncode == 0
            assert (
                lab.cli(
                    "tap", "fault", "st18-atc", "garbage", "ixl18->atc18", "02", "ff", "13"
                ).returncode
                == 0
            )
            assert (
                lab.cli("tap", "fault", "st18-ctc", "garbage", "ixl18->ctc", "02", "7f").returncode
                == 0
            )
            route = lab.ctc(
                {"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "11"}
            )
            assert route["ok"], route
            wait_until(
                "route 0111 reported set at the CTC",
                lambda: "0111" in lab.ctc({"cmd": "show", "station": 18})["summary"]["routes"],
                timeout=40,
            )
            for link in caps:
                assert lab.cli("tap", "fault", link, "clear").returncode == 0
            for m in monitors:
                _, err = m.communicate(timeout=WATCH + 60)
                assert m.returncode in (0, 1), err
        finally:
            for m in monitors:
                if m.poll() is None:
                    m.kill()
                    m.wait()
    for link, cap in caps.items():
        records = read_capture(cap).records
        profile = "ktcs-type2" if link.endswith("ctc") else "ktcs-type1"
        python = {d: decoded(data, profile) for d, data in streams(records).items()}
        frames = [r for recs in python.values() for r in recs if "garbage" not in r]
        assert len(frames) > 20, f"{link}: only {len(frames)} frames recorded"
        short = "ktcs2" if link.endswith("ctc") else "ktcs1"
        assert_agree(dissected(tshark_json(lua, cap), short), python)
        if short == "ktcs1":  # the bit errors and garbage came through as bad frames
            assert any(r.get("error") or "garbage" in r for recs in python.values() for r in recs)
