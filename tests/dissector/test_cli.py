"""`ktcs-bench dissector`: the file it writes, where --install puts it, and its errors."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import crcmod

from ktcs_bench.capture import CaptureRecord
from ktcs_bench.codec.crc import CrcSpec
from ktcs_bench.codec.profile import shipped_profiles
from ktcs_bench.dissector import crc_table, generate, lua_literal

from .harness import cli, run_tshark, tshark, tshark_json, write_pcapng

REQ = bytes.fromhex("02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03")
ACK = bytes.fromhex("02 00 00 10 06 00 03 87 00 00 03")


def test_crc_tables_are_crcmods_for_reflected_and_plain_crcs() -> None:
    specs = [
        CrcSpec("crc-16/arc", 0x18005, True, 0, 0, 0xBB3D),
        CrcSpec("crc-16/xmodem", 0x11021, False, 0, 0, 0x31C3),
        CrcSpec("crc-32", 0x104C11DB7, True, 0, 0xFFFFFFFF, 0xCBF43926),
        CrcSpec("crc-8", 0x107, False, 0, 0, 0xF4),
        CrcSpec("crc-24", 0x1864CFB, False, 0xB704CE, 0, None),
    ]
    for spec in specs:
        want = crcmod.Crc(spec.poly, spec.init, spec.reflect, spec.xor_out).table
        assert crc_table(spec) == list(want), spec.name


def test_lua_literals_escape_what_would_break_the_file() -> None:
    text = lua_literal({"a": 'say "hi"\\\n', "end": [1, 2], 3: None, "ok": True})
    assert text == '{ a = "say \\"hi\\"\\\\\\n", ["end"] = { 1, 2 }, ok = true }'


def test_out_writes_one_self_contained_file_naming_every_shipped_profile(tmp_path: Path) -> None:
    out = tmp_path / "k.lua"
    done = cli("dissector", "--out", str(out))
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    for name in shipped_profiles():
        assert f'["{name}"] = {{' in text
    assert "require" not in text and "dofile" not in text  # nothing to find at run time
    assert text == generate(list(shipped_profiles().values()))
    assert "ktcs1: ktcs-type1, ktcs-type1-fig7; ktcs2: ktcs-type2" in done.stdout


def test_install_goes_where_tshark_loads_personal_plugins_with_no_option(tmp_path: Path) -> None:
    home = tmp_path / "home"
    home.mkdir()
    env = {"HOME": str(home), "XDG_CONFIG_HOME": str(home / ".config")}
    done = cli("dissector", "--install", env=env)
    assert done.returncode == 0, done.stderr
    folders = subprocess.run(
        [tshark(), "-G", "folders"], capture_output=True, text=True, env={**os.environ, **env}
    ).stdout
    plugins = next(
        line.split(":", 1)[1].strip()
        for line in folders.splitlines()
        if line.startswith("Personal Lua Plugins")
    )
    assert Path(plugins, "ktcs.lua").is_file()
    assert f"wrote {plugins}/ktcs.lua" in done.stdout
    # a Type I capture opens decoded: no -X, no preference, no DLT_USER table entry
    cap = write_pcapng(
        tmp_path / "t1.pcapng",
        [CaptureRecord(1.0, "ixl>atc", REQ), CaptureRecord(1.02, "atc>ixl", ACK)],
        "type1",
    )
    packets = tshark_json(None, cap, home=home)
    layers = [p["_source"]["layers"]["ktcs1"] for p in packets]
    assert [(x["ktcs1.seq"], x["ktcs1.op_name"], x["ktcs1.crc_ok"]) for x in layers] == [
        ("16", "REQUEST_ALL", "1"),
        ("16", "ACK", "1"),
    ]
    assert layers[1]["ktcs1.arq.ack_to"] == "1"  # the ACK points at the frame it answers
    assert layers[0]["ktcs1.arq.acked_in"] == "2"


def test_without_the_dissector_the_same_capture_is_raw_data(tmp_path: Path) -> None:
    """The check above can fail: with no dissector the bytes are only `data`."""
    cap = write_pcapng(tmp_path / "t1.pcapng", [CaptureRecord(1.0, "ixl>atc", REQ)], "type1")
    packets = tshark_json(None, cap)
    assert "ktcs1" not in packets[0]["_source"]["layers"]


def test_usage_errors_exit_2(tmp_path: Path) -> None:
    assert cli("dissector").returncode == 2  # nowhere to write
    bad = cli("dissector", "--out", str(tmp_path / "x.lua"), "--profile", str(tmp_path / "no.yaml"))
    assert bad.returncode == 2 and "no.yaml" in bad.stderr
    dup = cli("dissector", "--out", str(tmp_path / "x.lua"), "--profile", "other.txt")
    assert dup.returncode == 2 and "FILE.yaml" in dup.stderr
    (tmp_path / "dir").mkdir()
    unwritable = cli("dissector", "--out", str(tmp_path / "dir"))
    assert unwritable.returncode == 2 and "cannot write" in unwritable.stderr
    assert not (tmp_path / "x.lua").exists()


def test_the_lua_checks_its_crc_tables_when_it_loads(tmp_path: Path) -> None:
    """A table that does not give the algorithm's check value stops the script at load time."""
    text = generate(list(shipped_profiles().values()))
    broken = tmp_path / "broken.lua"
    head, _, rest = text.partition("table = {")
    body, _, tail = rest.partition("}")
    zeros = ", ".join(["0x0000"] * 256)
    broken.write_text(head + "table = {" + zeros + "}" + tail)
    cap = write_pcapng(tmp_path / "t1.pcapng", [CaptureRecord(1.0, "ixl>atc", REQ)], "type1")
    done = run_tshark(broken, cap)
    assert "does not give its check value" in done.stdout + done.stderr
