"""decode/encode as a user runs them: real subprocesses, stdin, files, exit codes."""

import json
import random
import re
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.cli.decode import _cut_long_line
from ktcs_bench.codec.hextext import parse_hex_text


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


# -- hex input (issue 13) -----------------------------------------------------------------------
REQ = bytes.fromhex("02 04 00 10 00 00 00 00 FF FF 83 7B 00 00 03")
ACK = bytes.fromhex("02 00 00 10 06 00 03 87 00 00 03")
FIG7 = Path(__file__).resolve().parents[2] / "protocols" / "captures" / "fig7.hex"


def cli_in(cwd: Path, *args: str, stdin: str | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", *args],
        input=stdin, capture_output=True, text=True, timeout=60, cwd=cwd,
    )  # fmt: skip


def test_a_path_that_does_not_exist_is_an_error_not_hex(tmp_path: Path) -> None:
    for missing in ("fade", str(tmp_path / "nowhere" / "cap.hex"), "cap.hex", "./fade"):
        out = cli_in(tmp_path, "decode", "--profile", "ktcs-type1", missing)
        assert out.returncode == 2, (missing, out.stdout)
        assert f"no such file: {missing}" in out.stderr and "Traceback" not in out.stderr
        assert out.stdout == "", "nothing decoded before the error"


def test_hex_given_as_words_is_still_hex(tmp_path: Path) -> None:
    spaced = cli_in(tmp_path, "decode", "--json", "--profile", "ktcs-type1", "FA DE")
    assert json.loads(spaced.stdout) == {"garbage": "fade", "offset": 0}
    words = cli_in(tmp_path, "decode", "--json", "--profile", "ktcs-type1", *ACK.hex(" ").split())
    assert words.returncode == 0 and json.loads(words.stdout)["op_name"] == "ACK"
    (tmp_path / "fade").write_text(ACK.hex(" "), encoding="utf-8")  # a file by that name wins
    named = cli_in(tmp_path, "decode", "--json", "--profile", "ktcs-type1", "fade")
    assert named.returncode == 0 and json.loads(named.stdout)["op_name"] == "ACK"


def test_a_capture_saved_in_euc_kr_or_cp949_decodes_like_the_utf8_one(tmp_path: Path) -> None:
    text = FIG7.read_text(encoding="utf-8")
    want = cli_in(tmp_path, "decode", "--no-color", str(FIG7))
    assert "rx line 4" in want.stdout and "tx line 7" in want.stdout
    for encoding in ("euc-kr", "cp949"):
        path = tmp_path / f"fig7.{encoding}.hex"
        path.write_bytes(text.encode(encoding))
        with pytest.raises(UnicodeDecodeError):
            path.read_bytes().decode("utf-8")
        got = cli_in(tmp_path, "decode", "--no-color", str(path))
        assert (got.returncode, got.stdout) == (want.returncode, want.stdout)


def test_a_binary_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "capture.bin"
    path.write_bytes(REQ + bytes(range(256)))
    out = cli_in(tmp_path, "decode", str(path))
    assert out.returncode == 2 and "is not text" in out.stderr and "xxd" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_binary_tail_after_megabytes_of_text_is_refused_where_it_starts(tmp_path: Path) -> None:
    """Issue 21 item 8: hex text past the head and the first block read, then random bytes. The
    tail is refused (exit 2) at its offset, not decoded as hex with its lines skipped; from a
    pipe, the frames before it are printed as they streamed."""
    text = (ACK.hex(" ") + "\n").encode() * 40_000  # 1.36 MB: past the 1 MiB first read
    tail = random.Random(8).randbytes(3_000_000)
    path = tmp_path / "capture.hex"
    path.write_bytes(text + tail)
    out = cli_in(tmp_path, "decode", "--profile", "ktcs-type1", str(path))
    assert out.returncode == 2, (out.returncode, out.stdout[-300:])
    assert "non-hex lines skipped" not in out.stdout and "Traceback" not in out.stderr
    m = re.search(r"capture.hex stops being text at byte (\d+)", out.stderr)
    assert m is not None and "xxd" in out.stderr, out.stderr
    assert len(text) <= int(m.group(1)) < len(text) + 256  # where the tail starts
    piped = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "decode", "--json", "--profile", "ktcs-type1"],
        input=text + tail, capture_output=True, timeout=60, cwd=tmp_path,
    )  # fmt: skip
    assert piped.returncode == 2 and b"stdin stops being text at byte" in piped.stderr
    rows = [json.loads(line) for line in piped.stdout.splitlines()]
    assert rows and all(r["op_name"] == "ACK" and r["error"] is None for r in rows)


def test_text_in_every_form_is_never_taken_for_binary(tmp_path: Path) -> None:
    """The watch over the whole input leaves text alone: a CP949 console log with ANSI colours
    and tabs, an xxd dump and a hexdump -C dump, each megabytes long, decode as before."""
    console = (FIG7.read_text(encoding="utf-8") + "\x1b[32m\tok\x1b[0m\r\n") * 3000
    path = tmp_path / "console.hex"
    path.write_bytes(console.encode("cp949"))
    assert path.stat().st_size > 1 << 20
    out = cli_in(tmp_path, "decode", "--json", str(path))
    assert out.returncode == 1 and out.stderr == ""  # 1: the Fig. 7 reply is truncated
    assert len(out.stdout.splitlines()) >= 2 * 3000
    wire = tmp_path / "wire.bin"
    wire.write_bytes((REQ + ACK) * 60_000)
    for dump in ("xxd", "hexdump -C"):
        dumped = subprocess.run([*dump.split(), str(wire)], capture_output=True, check=True)
        assert len(dumped.stdout) > 1 << 20
        out = cli_in(tmp_path, "decode", "--json", "--profile", "ktcs-type1",
                     stdin=dumped.stdout.decode())  # fmt: skip
        assert out.returncode == 0, (dump, out.stderr)
        assert len(out.stdout.splitlines()) == 2 * 60_000


@pytest.mark.parametrize("dump", ["hexdump -C", "od -t x1", "od -A x -t x1z", "xxd"])
def test_dump_offsets_are_not_data(tmp_path: Path, dump: str) -> None:
    path = tmp_path / "cap.bin"
    path.write_bytes(REQ + ACK)
    text = subprocess.run([*dump.split(), str(path)], capture_output=True, text=True, check=True)
    out = cli_in(tmp_path, "decode", "--json", "--profile", "ktcs-type1", stdin=text.stdout)
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    assert [(r["op_name"], r["offset"], r["error"]) for r in rows] == [
        ("REQUEST_ALL", 0, None),
        ("ACK", len(REQ), None),
    ]
    assert out.returncode == 0


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (("--op", "LINK_TEST", "--items", "3=1"), "LINK_TEST carries no items"),
        (("--op", "CHANGE", "--field", "start=1"), "CHANGE carries no start"),
        (("--op", "ALL_INFO", "--items", "3=1"), "ALL_INFO carries no items"),
        (("--op", "CHANGE", "--statuses", "1,0"), "CHANGE carries no statuses"),
        (("--op", "REQUEST_ALL", "--field", "start=0", "--field", "count=4", "--field", "end=9"),
         "REQUEST_ALL carries no end"),
        (("--protocol", "type2", "--op", "IDENT", "--sub", "0", "--field", "station=20",
          "--field", "version=1", "--items", "1=1"), "IDENT carries no items"),
    ],
)  # fmt: skip
def test_encode_refuses_what_the_opcode_does_not_carry(args: tuple[str, ...], problem: str) -> None:
    out = cli("encode", "--seq", "1", *args)
    assert out.returncode == 2 and problem in out.stderr, out.stderr
    assert out.stdout == "" and "Traceback" not in out.stderr


@settings(max_examples=300)
@given(
    data=st.binary(min_size=1, max_size=200),
    form=st.sampled_from(["compact", "spaced", "angle", "hexlog", "console"]),
    cuts=st.lists(st.integers(20, 2000), min_size=1, max_size=6),
)
def test_a_line_too_long_to_hold_is_cut_into_lines_that_read_the_same(
    data: bytes, form: str, cuts: list[int]
) -> None:
    """decode cuts a line that has no end in sight (over 1 MiB, so never inside a line's prefix,
    here under 20 characters); the pieces read as the same bytes and the same one record (bare
    hex continues the record its line began)."""
    body = {"compact": data.hex(), "spaced": data.hex(" "), "angle": "".join(f"<{b:02X}>" for b in data),
            "hexlog": f"1.5 a>b {data.hex(' ')}", "console": f"수신 = {data.hex()}"}[form]  # fmt: skip
    lines, rest = [], body
    for at in cuts:  # cut where decode would, once the line is `at` characters long
        head, rest2 = _cut_long_line(rest[:at])
        if not head:
            continue
        lines.append(head)
        rest = rest2 + rest[at:]
    lines.append(rest)
    whole, pieces = parse_hex_text(body), parse_hex_text("\n".join(lines))
    assert pieces.data == whole.data == data
    assert len(pieces.chunks) == len(whole.chunks) == 1
    assert pieces.chunks[0].direction == whole.chunks[0].direction


def test_a_payload_that_does_not_parse_fails_the_same_in_text_and_json() -> None:
    """A CHANGE whose CRC checks but whose DATA is not whole items is a failed check either way."""
    frame = "02 02 00 05 02 00 03 00 6f 51 00 00 03"  # CHANGE, 2 item bytes, CRC good
    text = cli("decode", "--profile", "ktcs-type1", frame)
    as_json = cli("decode", "--json", "--profile", "ktcs-type1", frame)
    assert json.loads(as_json.stdout)["error"] == "format"
    assert "ERROR: format" in text.stdout and "not a multiple of 3" in text.stdout
    assert text.returncode == as_json.returncode == 1
