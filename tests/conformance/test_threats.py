"""The seven EN 50159 threats against a lab of real emulator processes, through real taps:
every threat is caught by its defence and the application outcome is safe."""

from __future__ import annotations

import json

from ktcs_bench.conformance.threats import THREATS

from .conftest import cli


def test_every_threat_caught(tmp_path) -> None:  # type: ignore[no-untyped-def]
    table = tmp_path / "threats.md"
    run = cli("threats", "--json", "--markdown", str(table), timeout=120)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    results = json.loads(run.stdout)
    assert [r["threat"] for r in results] == list(THREATS)
    for r in results:
        assert r["caught"] and r["safe"], r
    text = table.read_text()
    assert text.startswith("| threat |") and text.count("\n") == len(THREATS) + 2
    defences = {r["threat"]: r["defence"] for r in results}
    assert defences["corruption"].startswith("CRC")
    assert defences["masquerade"].startswith("IDENT")
    assert defences["delay"].startswith("timeout")
    assert defences["repetition"].startswith("SEQ")
