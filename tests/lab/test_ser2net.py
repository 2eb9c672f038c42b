"""Issue 16: a Type I device behind Debian's `ser2net` (RFC 2217) on another host, reached by the
lab across the network as real labs reach a serial device. The hosts are Linux namespaces made
without root where user namespaces are allowed (`unshare --user --map-root-user`); what runs in
them, and what is checked, is `ser2net_hosts.py`.

This test is never skipped: ser2net, util-linux's `unshare`/`nsenter` and iproute2 are part of the
set-up (`.ci/system-deps`), and a machine that refuses the namespaces fails here, saying so."""

from __future__ import annotations

from pathlib import Path

from tests.lab.netns import require_namespaces, run_driver

TIMEOUT = 300.0


def test_a_type1_device_behind_ser2net_on_another_host(tmp_path: Path) -> None:
    require_namespaces(("ser2net",))
    seen = run_driver("tests.lab.ser2net_hosts", tmp_path, TIMEOUT)
    assert seen["alive"] and seen["after_outage"]["atc18"]["open"], seen
    assert seen["code_TC1853A"][1] > seen["code_TC1853A"][0], seen
