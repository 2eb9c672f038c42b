"""`ktcs-bench threats --target` against the real `lab up`: the seven threats through the lab's
own taps (a Type I link and a Type II link of station 20), the outcome read from the lab's devices,
and the lab healthy again afterwards."""

from __future__ import annotations

import json
from pathlib import Path

from ktcs_bench.capture.hexlog import parse_hex_log
from ktcs_bench.codec import Frame, StreamDecoder, get_profile
from ktcs_bench.threats import THREATS

from .conftest import start_lab, wait_until


def test_threats_against_the_running_lab(tmp_path: Path) -> None:
    with start_lab(tmp_path, "threatlab") as lab:
        table = tmp_path / "threats.md"
        run = lab.cli("threats", "--target", "st20-atc", "--target", "st20-ctc", "--json",
                      "--markdown", str(table), timeout=240)  # fmt: skip
        assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
        report = json.loads(run.stdout)
        assert [(t["tap"], t["dut"], t["application"]) for t in report["targets"]] == [
            ("st20-atc", "ixl20", "lab threatlab (devices ixl20, ctc)"),
            ("st20-ctc", "ctc", "lab threatlab (devices ixl20, ctc)"),
        ]
        results = report["results"]
        assert [r["threat"] for r in results] == list(THREATS)
        for r in results:
            assert r["ran"] and r["caught"] and r["safe"] is True, r
        masquerade = " ".join(results[list(THREATS).index("masquerade")]["evidence"])
        assert "IDENT station 20 → refused" in masquerade and "log names" in masquerade
        assert table.read_text().count("| yes |") >= len(THREATS)
        # the injections are in the lab's own capture of the link: the corrupted CHANGE (bad CRC)
        # went to the IXL, and the IXL's NAK came back
        capture = lab.run_dir / "labs" / "threatlab" / "captures" / "st20-atc.hex"
        records = parse_hex_log(capture.read_text()).records
        t1 = get_profile("ktcs-type1")

        def frames(direction: str) -> list[Frame]:
            stream = b"".join(r.data for r in records if r.direction == direction)
            return [f for f in StreamDecoder(t1).feed(stream) if isinstance(f, Frame)]

        assert any(f.error == "crc" and f.seq == 0x77 for f in frames("atc20>ixl20"))
        nak = t1.opcodes.by_name["NAK"].op
        assert any(f.op == nak and f.data[:1] == b"\x01" for f in frames("ixl20>atc20"))
        # the ATC as the device under test: the IXL's frames are forged; the ATC's state is not
        # one the bench reads, so the outcome is the wire's alone
        run = lab.cli("threats", "--target", "st20-atc", "--dut", "atc20", "--threat",
                      "corruption", "--threat", "insertion", "--json", timeout=120)  # fmt: skip
        assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
        report = json.loads(run.stdout)
        assert [(t["dut"], t["peer"], t["application"]) for t in report["targets"]] == [
            ("atc20", "ixl20", None)
        ]
        for r in report["results"]:
            assert r["ran"] and r["caught"] and r["safe"] is None, r
        # and the lab is whole again: every station synced, the line clear
        wait_until(
            "every station synced again, the line clear",
            lambda: all(s["link"] == "up" and s["synced"] and not s["occupied"]
                        for s in lab.ctc({"cmd": "status"})["status"]["stations"].values()),
            timeout=30,
        )  # fmt: skip
