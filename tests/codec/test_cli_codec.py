"""decode/encode as a user runs them: real subprocesses, stdin, files, exit codes."""

import json
import subprocess
import sys
from pathlib import Path


def cli(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args],
        input=stdin, capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_encode_then_decode_is_the_identity_on_the_command_line() -> None:
    enc = cli(
        "encode", "--seq", "5", "--op", "CHANGE", "--items", "3=1,260=0", "--format", "compact"
    )
    assert enc.returncode == 0
    assert enc.stdout.strip() == "0206000502000300010401001858000003"
    dec = cli("decode", "--json", "--profile", "ktcs-type1", enc.stdout.strip())
    row = json.loads(dec.stdout)
    assert row["op_name"] == "CHANGE" and row["items"] == [[3, 1], [260, 0]] and row["seq"] == 5
    assert dec.returncode == 0


def test_decode_from_stdin_as_xxd_with_garbage(tmp_path: Path) -> None:
    wire = bytes.fromhex("ff") + bytes.fromhex("02 03 02 40 00 E9 84".replace(" ", ""))
    path = tmp_path / "cap.bin"
    path.write_bytes(wire)
    xxd = subprocess.run(["xxd", str(path)], capture_output=True, text=True)
    text = xxd.stdout if xxd.returncode == 0 else "00000000: ff02 0302 4000 e984  ........\n"
    out = cli("decode", "--json", "--protocol", "type2", stdin=text)
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    assert rows[0] == {"garbage": "ff", "offset": 0}
    assert (
        rows[1]["op_name"] == "HEARTBEAT"
        and rows[1]["offset"] == 1
        and rows[1]["profile"] == "ktcs-type2"
    )


def test_decode_shows_chart_names(tmp_path: Path) -> None:
    chart = tmp_path / "chart.yaml"
    chart.write_text(
        "chart: t\nprotocol: type1\ndirection: ATC->IXL\ncodes:\n"
        "  - {name: TC1851, type: TC}\n  - {name: TC1853A, type: TC}\n  - {name: TC1853B, type: TC}\n",
        encoding="utf-8",
    )
    out = cli("decode", "--profile", "ktcs-type1", "--chart", str(chart),
              "02 06 00 05 02 00 03 00 01 04 01 00 18 58 00 00 03")  # fmt: skip
    assert "3 TC1853B=1" in out.stdout and "260=0" in out.stdout
    assert "Packet = [18]-[58], Cal = [18]-[58]" in out.stdout


def test_decode_without_hex_is_a_usage_error() -> None:
    out = cli("decode", "no hex here")
    assert out.returncode == 2 and "no hex bytes" in out.stderr and "Traceback" not in out.stderr


def test_help_teaches() -> None:
    out = cli("--help")
    assert "decode" in out.stdout and "encode" in out.stdout and "exit codes" in out.stdout
