"""Two hosts on one machine: a lab on one, an ATC behind Debian's `ser2net` (RFC 2217) on the other.

Run by `test_ser2net.py` through `netns.run_driver` (`unshare --user --map-root-user --net --pid
--fork --kill-child --mount-proc python -m tests.lab.ser2net_hosts TMP`: no root needed where
user namespaces are allowed). In there this process is the lab's host: a network namespace of its own (10.99.0.1) and
pid 1 of a pid namespace, so when it ends, however it ends, the kernel ends every process it
started and both namespaces go with them. The device's host is a second network namespace
(10.99.0.2), joined to the first by a veth pair. On it run the emulated ATC (its Type I line a pty)
and `ser2net`, serving that pty as RFC 2217 on 10.99.0.2:4000. The lab file names the ATC
`external: {serial: "rfc2217://10.99.0.2:4000?..."}`, so the lab's tap reaches the serial line
across the network, as a real lab reaches a device at a remote serial server.

Prints one JSON line of what it saw and exits 0, or prints why it failed and exits 1.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Any

from ktcs_bench.runtime import private_dir, read_token
from tests.lab.conftest import request, start_lab, wait_until
from tests.lab.netns import (
    DEVICE_IP,
    LAB_IP,
    RAILS_PORT,
    DeviceHost,
    driver_main,
    emulated_atc,
    reachable,
    sh,
    station18_lab,
)  # fmt: skip

SER2NET_PORT = 4000
# ser2net's serial device here is a pty, which has no modem lines: it cannot acknowledge DTR/RTS,
# so pyserial is told not to wait for that (a real UART behind ser2net would acknowledge them)
URL = f"rfc2217://{DEVICE_IP}:{SER2NET_PORT}?ign_set_control"


def main(tmp: Path) -> dict[str, Any]:
    name, run_dir = "ser2netlab", tmp / "run"
    os.environ["KTCS_BENCH_RUN_DIR"] = str(run_dir)
    token = private_dir(run_dir / "labs" / name) / "token"  # the lab's; the ATC shares it
    seen: dict[str, Any] = {}
    host = DeviceHost()
    try:
        ready = emulated_atc(host, tmp, token, f"{LAB_IP}:{RAILS_PORT}")[1]
        pty = ready["ptys"]["ixl"]
        conf = tmp / "ser2net.yaml"  # ser2net reads only files named *.yaml
        conf.write_text(
            "connection: &atc18\n"
            f"    accepter: telnet(rfc2217),tcp,{DEVICE_IP},{SER2NET_PORT}\n"
            "    enable: on\n"
            "    options:\n"
            "      kickolduser: true\n"
            f"    connector: serialdev,{pty},9600n81,local\n",
            encoding="utf-8",
        )
        ser2net = host.spawn(["ser2net", "-n", "-d", "-u", "-c", str(conf)],
                             stdout=open(tmp / "ser2net.log", "w"), stderr=subprocess.STDOUT)  # noqa: SIM115  # fmt: skip
        wait_until(
            "ser2net serving on the device's host", lambda: reachable(DEVICE_IP, SER2NET_PORT)
        )
        assert not reachable("127.0.0.1", SER2NET_PORT), "the device's port is on our loopback"
        seen["ser2net"] = {"pid": ser2net.pid, "serves": f"{DEVICE_IP}:{SER2NET_PORT}", "pty": pty}

        lab_file = station18_lab(tmp, name, f"serial: '{URL}'")
        with start_lab(tmp, name, path=lab_file) as lab:

            def alive() -> bool:
                return bool(lab.lab({"cmd": "status"})["status"]["devices"]["atc18"]["alive"])

            def atc_status() -> dict[str, Any]:
                answer = request(ready["control"], {"cmd": "status"}, token=read_token(token))
                return answer["status"]  # type: ignore[no-any-return]

            def signal_01() -> str:
                return str(lab.ctc({"cmd": "show", "station": 18})["summary"]["signals"]["01"])

            assert lab.links["st18-atc"]["b_end"] == URL, lab.links["st18-atc"]
            wait_until(
                "ixl18's ATC link up across the network",
                lambda: lab.status("ixl18")["links"]["atc"],
            )
            wait_until("atc18 external and alive in lab status", alive)
            wait_until(
                "the ATC on the lab's rails, across the network", lambda: atc_status()["rails"]
            )
            wait_until("point 31 detected normal at the CTC",
                       lambda: lab.ctc({"cmd": "show", "station": 18})["summary"]["points"]["31"] == "normal")  # fmt: skip
            stop = atc_status()["codes"]["TC1853A"][1]
            route = lab.ctc({"cmd": "route", "action": "set", "station": 18, "entry": "01", "exit": "11"})  # fmt: skip
            assert route["ok"] and route["result"] == "accepted", route
            wait_until("signal 01 clears", lambda: signal_01() != "R")
            wait_until(
                "the ATC's code on TC1853A steps up",
                lambda: atc_status()["codes"]["TC1853A"][1] > stop,
            )
            seen["code_TC1853A"] = [stop, atc_status()["codes"]["TC1853A"][1]]
            tap = lab.lab({"cmd": "status"})["status"]["taps"]["st18-atc"]
            assert tap["external_ends"]["atc18"]["open"] and tap["records"] > 0, tap
            # the device's network goes down: the link fails, the signal goes to stop; when the
            # network is back the same connection carries the link again
            sh(*host.inside(["ip", "link", "set", "dev0", "down"]))
            wait_until("atc18 not alive with its network down", lambda: not alive())
            wait_until("signal 01 to stop with the ATC unreachable", lambda: signal_01() == "R")
            sh(*host.inside(["ip", "link", "set", "dev0", "up"]))
            wait_until("atc18 alive again with its network back", alive, timeout=90)
            wait_until("signal 01 clears again", lambda: signal_01() != "R", timeout=60)
            seen["after_outage"] = lab.lab({"cmd": "status"})["status"]["taps"]["st18-atc"][
                "external_ends"
            ]
            seen["alive"] = True
        return seen
    finally:
        host.close()


if __name__ == "__main__":
    driver_main(main)
