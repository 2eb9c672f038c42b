"""A small lab of real processes for `threats` run without `--target`: CTC, one station's IXL and
ATC, the track circuits, with a pty tap on the Type I link (IXL ⇄ ATC) and a TCP tap on the Type
II link (IXL ⇄ CTC). The campaign attacks it exactly as it attacks a running link: through the taps'
control ports (`targets()`), reading the devices over their control ports.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ktcs_bench import kinds
from ktcs_bench.errors import PeerError
from ktcs_bench.lab.processes import Child, emulator_argv
from ktcs_bench.lab.topology import load_lab, resolve_lab_path
from ktcs_bench.tap.pty import PtyTap
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.threats.application import Application, host_port
from ktcs_bench.threats.campaign import ThreatTarget
from ktcs_bench.threats.wire import WireTap, wait_for

READY_TIMEOUT = 15.0


class ThreatLab:
    """`with ThreatLab(18) as lab: targets = lab.targets()`; everything stops on exit."""

    def __init__(self, station: int = 18, lab: str | None = None) -> None:
        self.station = station
        self.lab = lab
        self.line = load_lab(resolve_lab_path(lab)).load_line()
        self.procs: list[Child] = []
        self.taps: list[PtyTap | TcpTap] = []
        self.wires: list[WireTap] = []
        self._logs = tempfile.TemporaryDirectory(prefix="ktcs-threats-")

    def __enter__(self) -> ThreatLab:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _spawn(self, kind: str, *args: str) -> Child:
        extra = ["--lab", self.lab] if self.lab else []
        name = f"{kind}-{len(self.procs)}"
        child = Child(
            name, emulator_argv(kind, *args, *extra), Path(self._logs.name) / f"{name}.log"
        )
        self.procs.append(child)
        child.start()
        return child

    def _start(self) -> None:
        st = str(self.station)
        self.ctc = self._spawn(kinds.CTC, "--listen", "127.0.0.1:0")
        ctc_address = host_port(self.ctc.ready["listen"])
        self.t2 = TcpTap(("127.0.0.1", 0), ctc_address, names=(kinds.IXL, kinds.CTC),
                         profile="ktcs-type2", name=f"st{st}-ctc")  # fmt: skip
        self.t1 = PtyTap(names=(kinds.IXL, kinds.ATC), profile="ktcs-type1", name=f"st{st}-atc")
        for tap in (self.t2, self.t1):
            tap.start()
            self.taps.append(tap)
        assert self.t2.listen_address is not None
        lh, lp = self.t2.listen_address
        rails = self._spawn(kinds.TRACKCIRCUIT, "--listen", "127.0.0.1:0").ready["listen"]
        self._spawn(kinds.ATC, "--station", st, "--unpaced", "--link", f"ixl={self.t1.paths[kinds.ATC]}",
                    "--link", f"rails=tcp://{rails}")  # fmt: skip
        self.ixl = self._spawn(kinds.IXL, "--station", st, "--unpaced", "--link",
                               f"atc={self.t1.paths[kinds.IXL]}", "--link", f"ctc=tcp://{lh}:{lp}")  # fmt: skip
        self.app = Application.of_station(
            self.line, self.station, kinds.ATC, ixl=host_port(self.ixl.ready["control"]),
            ctc=host_port(self.ctc.ready["control"]), ctc_log=self.ctc.log_path,
            source="the threat lab",
        )  # fmt: skip
        if not wait_for(self.healthy, READY_TIMEOUT, 0.2):
            raise PeerError("the threat lab did not come up (links, resync)")

    def healthy(self) -> bool:
        s, v = self.app.ixl_status(), self.app.ctc_view()
        return bool(s and v and s["links"].get(kinds.ATC) and s["links"].get(kinds.CTC)
                    and self.app.settled(s) and v["summary"]["synced"])  # fmt: skip

    def targets(self) -> list[ThreatTarget]:
        """The Type I link (device under test: the IXL) and the Type II link (the CTC)."""
        out = []
        for tap, dut in ((self.t1, kinds.IXL), (self.t2, kinds.CTC)):
            assert tap.control_address is not None
            wire = WireTap(tap.control_address)
            self.wires.append(wire)
            out.append(ThreatTarget(wire, dut, self.app, station=self.station))
        return out

    def close(self) -> None:
        for w in self.wires:
            w.close()
        for p in reversed(self.procs):
            p.stop()
        for tap in self.taps:
            tap.stop()
        self._logs.cleanup()
