"""`--link PEER=...` names a peer by its link role or by its kind (issue 22 part 1): the trackside
is `trackside` everywhere a user types a kind, and its link role `io` (the charts `ixl_to_io`, the
`st20-io` taps, the `io` of a status's links) is still taken as before."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from .conftest import Proc, cli


@pytest.mark.parametrize("word", ["trackside", "io"])
def test_an_ixl_links_its_trackside_by_kind_or_by_role(
    spawn: Callable[..., Proc], word: str
) -> None:
    ixl = spawn("emulator", "ixl", "--station", "18", "--unpaced",
                "--link", "atc=pty", "--link", f"{word}=pty")  # fmt: skip
    assert set(ixl.ready["ptys"]) == {"atc", "io"}


def test_a_peer_that_is_neither_a_role_nor_a_kind_with_one_is_refused() -> None:
    for word in ("relay", "trackcircuit"):
        r = cli("emulator", "ixl", "--station", "18", "--link", f"{word}=pty")
        assert r.returncode == 2, r.stderr
        assert (
            f"--link {word}=...: unknown peer (use ctc, ixl, atc, io, west, east, rails" in r.stderr
        )


def test_the_suite_takes_its_ixl_peer_by_kind_or_by_role() -> None:
    for word in ("trackside", "io", "atc"):
        r = cli("conformance", "--role", "ixl", "--peer", word, "--list")
        assert r.returncode == 0, r.stderr
    r = cli("conformance", "--role", "ixl", "--peer", "relay", "--list")
    assert r.returncode == 2 and "invalid choice: 'relay'" in r.stderr
