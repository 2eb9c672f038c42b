"""The tap's command words, parsed without a tap: words in, a command and its fault out."""

from __future__ import annotations

import pytest

from ktcs_bench.errors import UsageError
from ktcs_bench.faults import BitErrors, Cut, DropFrame, DuplicateFrame, InsertGarbage
from ktcs_bench.tap import parse_command


def test_control_commands_parse_to_faults() -> None:
    names = ("ixl", "atc")
    assert parse_command("ber 1e-3", names).fault == BitErrors(1e-3)
    assert parse_command("drop-frame ixl->atc", names).fault == DropFrame(1, direction="ixl>atc")
    assert parse_command("duplicate 2 atc>ixl", names).fault == DuplicateFrame(
        2, direction="atc>ixl"
    )
    cmd = parse_command("garbage ixl->atc 02 ff 00", names)
    assert cmd.fault == InsertGarbage(b"\x02\xff\x00", direction="ixl>atc")
    assert parse_command("cut", names).fault == Cut()
    assert parse_command("send atc>ixl 0203", names).data == b"\x02\x03"
    assert parse_command("subscribe history", names).history
    for bad in ["", "explode", "ber", "ber x", "ber 2", "drop-frame a->b", "send 02", "cut 3",
                "drop-frame 0", "garbage ixl->atc zz"]:  # fmt: skip
        with pytest.raises(UsageError):
            parse_command(bad, names)
