"""The seven EN 50159 threats, each injected through a tap into a running link between our
emulators, each reported with the defence that caught it and the application outcome.

`ThreatLab` starts a small lab of real processes -- CTC, one station's IXL and ATC, the track
circuits -- with a pty
tap on the Type I link (IXL ⇄ ATC) and a TCP tap on the Type II link (IXL ⇄ CTC). Each threat
function injects one threat, reads the tap's record of the wire (what the receiver did: ACK, NAK,
REQUEST_ALL, retransmission, refusal) and the devices' own state over their control ports (what
the application did), and returns a `ThreatResult`.
"""

from __future__ import annotations

import asyncio
import socket
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ktcs_bench.capture.records import CaptureRecord
from ktcs_bench.charts.generate import station_chart
from ktcs_bench.codec import Frame, FrameCodec, StreamDecoder, get_profile
from ktcs_bench.emulator import jsonlines
from ktcs_bench.errors import PeerError
from ktcs_bench.lab.processes import Child, emulator_argv
from ktcs_bench.lab.topology import load_lab, resolve_lab_path
from ktcs_bench.tap import Delay, DropFrame, DuplicateFrame, PtyTap, ReorderFrames, TcpTap

T1 = get_profile("ktcs-type1")
T2 = get_profile("ktcs-type2")
READY_TIMEOUT = 20.0


@dataclass
class ThreatResult:
    threat: str
    link: str
    injection: str
    defence: str
    caught: bool
    outcome: str
    safe: bool
    evidence: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"threat": self.threat, "link": self.link, "injection": self.injection,
                "defence": self.defence, "caught": self.caught, "outcome": self.outcome,
                "safe": self.safe, "evidence": self.evidence}  # fmt: skip


class _Proc(Child):
    """One emulator process of the threat lab (a `lab.processes.Child`), with its control port."""

    def __init__(self, args: list[str], log_dir: Path) -> None:
        name = f"{args[0]}-{len(list(log_dir.glob('*.log')))}"
        super().__init__(name, emulator_argv(*args), log_dir / f"{name}.log")
        self.start()
        host, _, port = self.ready["control"].rpartition(":")
        self.control = (host, int(port))

    def ask(self, obj: dict[str, Any]) -> dict[str, Any]:
        return asyncio.run(jsonlines.request(*self.control, obj, timeout=5.0))


def _wait(pred: Callable[[], bool], timeout: float, step: float = 0.1) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()


class ThreatLab:
    """CTC + IXL + ATC of one station (and the track circuits, so the line reads clear), Type I through a `PtyTap`, Type II through a `TcpTap`."""

    def __init__(self, station: int = 18, lab: str | None = None) -> None:
        self.station = station
        line = load_lab(resolve_lab_path(lab)).load_line()
        view = line.view(station)
        self.tcs = [
            c.name for c in station_chart(view, "atc_to_ixl").codes if c.name.startswith("TC")
        ]
        self.atc_chart = station_chart(view, "atc_to_ixl")
        self.ctc_chart = station_chart(view, "ixl_to_ctc")
        self.procs: list[_Proc] = []
        self.taps: list[PtyTap | TcpTap] = []
        self._logs = tempfile.TemporaryDirectory(prefix="ktcs-threats-")
        self.lab = lab

    def __enter__(self) -> ThreatLab:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _spawn(self, *args: str) -> _Proc:
        extra = ["--lab", self.lab] if self.lab else []
        p = _Proc([*args, *extra], Path(self._logs.name))
        self.procs.append(p)
        return p

    def _start(self) -> None:
        st = str(self.station)
        self.ctc = self._spawn("ctc", "--listen", "127.0.0.1:0")
        host, _, port = self.ctc.ready["listen"].rpartition(":")
        self.ctc_address = (host, int(port))
        self.t2 = TcpTap(("127.0.0.1", 0), self.ctc_address, names=("ixl", "ctc"), profile=T2)
        self.t1 = PtyTap(names=("ixl", "atc"), profile=T1)
        for tap in (self.t2, self.t1):
            tap.start()
            self.taps.append(tap)
        assert self.t2.listen_address is not None
        lh, lp = self.t2.listen_address
        rails = self._spawn("trackcircuit", "--listen", "127.0.0.1:0").ready["listen"]
        self.atc = self._spawn("atc", "--station", st, "--unpaced", "--link",
                               f"ixl={self.t1.paths['atc']}", "--link", f"rails=tcp://{rails}")  # fmt: skip
        self.ixl = self._spawn("ixl", "--station", st, "--unpaced", "--link",
                               f"atc={self.t1.paths['ixl']}", "--link", f"ctc=tcp://{lh}:{lp}")  # fmt: skip
        if not _wait(lambda: self.healthy(), 15.0, 0.2):
            raise PeerError("the threat lab did not come up (links, resync)")

    def close(self) -> None:
        for p in reversed(self.procs):
            p.stop()
        for tap in self.taps:
            tap.stop()
        self._logs.cleanup()

    # -- what the application shows -------------------------------------------------------------
    def ixl_status(self) -> dict[str, Any]:
        status: dict[str, Any] = self.ixl.ask({"cmd": "status"})["status"]
        return status

    def ctc_view(self) -> dict[str, Any]:
        return self.ctc.ask({"cmd": "show", "station": self.station})

    def views_agree(self) -> bool:
        ixl = {self.ctc_chart.name_of(int(k)): v for k, v in self.ixl_status()["ctc_state"].items()}
        return bool(self.ctc_view()["state"] == ixl)

    def healthy(self) -> bool:
        s = self.ixl_status()
        v = self.ctc_view()["summary"]
        return bool(s["links"].get("atc") and s["links"].get("ctc") and not s["occupied"]
                    and v["link"] == "up" and v["synced"])  # fmt: skip

    def ctc_log(self) -> str:
        return self.ctc.log_path.read_text(errors="replace")


def _frames(tap: PtyTap | TcpTap, since: int, direction: str) -> list[tuple[float, Frame]]:
    profile = T1 if isinstance(tap, PtyTap) else T2
    out = []
    rec: CaptureRecord
    for rec in tap.records()[since:]:
        if rec.direction != direction:
            continue
        for f in StreamDecoder(profile).feed(rec.data):
            if isinstance(f, Frame):
                out.append((rec.time or 0.0, f))
    return out


def _name(f: Frame, t2: bool = False) -> str:
    op = (T2 if t2 else T1).opcodes.get(f.op) if f.op is not None else None
    return op.name if op else "?"


def _is_data1(f: Frame) -> bool:
    return f.ok and _name(f) not in ("ACK", "NAK")


# -- the threats ----------------------------------------------------------------------------------
def repetition(lab: ThreatLab) -> ThreatResult:
    tap = lab.t1
    mark = len(tap.records())
    tap.inject(DuplicateFrame(direction="atc>ixl"))
    _wait(lambda: any(_is_data1(f) for _, f in _frames(tap, mark, "atc>ixl")), 3.0)
    time.sleep(0.4)
    data = [f for _, f in _frames(tap, mark, "atc>ixl") if _is_data1(f)]
    twice = next(
        (f for i, f in enumerate(data) if any(g.raw == f.raw for g in data[i + 1 :])), None
    )
    back = [f for _, f in _frames(tap, mark, "ixl>atc")]
    acks = [f for f in back if _name(f) == "ACK" and twice is not None and f.seq == twice.seq]
    naks = [f for f in back if _name(f) == "NAK"]
    resync = [f for f in back if _name(f) == "REQUEST_ALL"]
    caught = twice is not None and len(acks) >= 2 and not naks and not resync
    s = lab.ixl_status()
    safe = bool(s["links"]["atc"]) and not s["occupied"]
    ev = [f"{_name(twice)} SEQ 0x{twice.seq:02X} delivered twice by the tap" if twice else
          "no frame was repeated", f"IXL ACKs of that SEQ: {len(acks)}, NAKs: {len(naks)}, "
          f"REQUEST_ALL: {len(resync)}"]  # fmt: skip
    return ThreatResult("repetition", "Type I ATC→IXL", "tap: duplicate 1 atc>ixl",
                        "SEQ: the repeat of the last accepted SEQ is ACKed, not delivered", caught,
                        "link stays up, IXL state unchanged" if safe else f"IXL state changed: {s}",
                        safe, ev)  # fmt: skip


def deletion(lab: ThreatLab) -> ThreatResult:
    tap = lab.t1
    before = [f.seq for _, f in _frames(tap, 0, "atc>ixl") if _is_data1(f)]
    mark = len(tap.records())
    tap.inject(DropFrame(direction="atc>ixl"))
    time.sleep(2.5)  # an ATC LINK_TEST or an ACK is due within the link-test period
    ixl_data = [f.raw for _, f in _frames(tap, mark, "ixl>atc") if _is_data1(f)]
    atc_data = [f.seq for _, f in _frames(tap, mark, "atc>ixl") if _is_data1(f)]
    resync = any(_name(f) == "REQUEST_ALL" for _, f in _frames(tap, mark, "ixl>atc"))
    if len(ixl_data) != len(set(ixl_data)):
        retx, how = True, "an ACK was lost: the IXL retransmitted its frame with the same SEQ"
    elif before and atc_data and before[-1] is not None and atc_data[0] == (before[-1] + 1) % 256:
        retx = not resync and lab.ixl_status()["links"]["atc"]
        how = (f"an ATC frame was lost: SEQ 0x{atc_data[0]:02X} arrived after the ACK timeout "
               "(retransmitted), no SEQ gap at the IXL")  # fmt: skip
    else:
        retx, how = False, "no retransmission seen"
    ev = [f"one frame dropped; {how}"]
    # Sustained loss: cut the ATC's direction past T_MAX; the IXL must go fail-safe.
    tap.cut("atc>ixl")
    down = _wait(lambda: not lab.ixl_status()["links"]["atc"], 8.0, 0.2)
    occupied = lab.ixl_status()["occupied"]
    failsafe = down and set(lab.tcs) <= set(occupied)
    ev.append(f"cut atc>ixl: IXL link {'down' if down else 'still up'}; occupied: {len(occupied)} "
              f"of {len(lab.tcs)} track circuits")  # fmt: skip
    tap.restore("atc>ixl")
    back = _wait(
        lambda: lab.ixl_status()["links"]["atc"] and not lab.ixl_status()["occupied"], 10.0, 0.2
    )
    ev.append("restored: link up and occupancy rebuilt from ALL_INFO" if back else "not recovered")
    return ThreatResult("deletion", "Type I ATC→IXL", "tap: drop-frame 1 atc>ixl; cut atc>ixl",
                        "timeout: ACK timeout → retransmission; T_MAX silence → link down",
                        retx and down, "fail-safe: every track circuit of the link taken as "
                        "occupied while lost; rebuilt on recovery" if failsafe and back
                        else "NOT fail-safe", failsafe and back, ev)  # fmt: skip


def insertion(lab: ThreatLab) -> ThreatResult:
    tap = lab.t1
    last = [f.seq for _, f in _frames(tap, 0, "atc>ixl") if _is_data1(f) and f.seq is not None]
    seq = ((last[-1] if last else 0) + 100) % 256
    code = lab.atc_chart.number_of(lab.tcs[0])
    frame = FrameCodec(T1).encode_message(seq, "CHANGE", items=[[code, 1]])
    mark = len(tap.records())
    tap.send("atc>ixl", frame)
    asked = _wait(
        lambda: any(_name(f) == "REQUEST_ALL" for _, f in _frames(tap, mark, "ixl>atc")), 3.0
    )
    answered = _wait(
        lambda: any(_name(f) == "ALL_INFO" for _, f in _frames(tap, mark, "atc>ixl")), 3.0
    )
    rebuilt = _wait(lambda: not lab.ixl_status()["occupied"], 3.0)
    ev = [f"inserted CHANGE {lab.tcs[0]}=1 with SEQ 0x{seq:02X} (out of sequence)",
          f"IXL: SEQ gap → REQUEST_ALL {'sent' if asked else 'NOT sent'}; ATC ALL_INFO "
          f"{'sent' if answered else 'not seen'}"]  # fmt: skip
    return ThreatResult("insertion", "Type I ATC→IXL", "tap: send atc>ixl (a well-formed CHANGE)",
                        "SEQ: gap → REQUEST_ALL, state rebuilt from the ATC's ALL_INFO",
                        asked and answered, "inserted value replaced by the true state within one "
                        "exchange (Type I has no source authentication: it was acted on until then)"
                        if rebuilt else "inserted value persists", rebuilt, ev)  # fmt: skip


def resequencing(lab: ThreatLab) -> ThreatResult:
    tap = lab.t2
    mark = len(tap.records())
    full_before = lab.ctc_view()["summary"]
    tap.inject(ReorderFrames(direction="ixl>ctc"))
    asked = _wait(lambda: any(f.ok and _name(f, True) == "REQUEST_ALL"
                              for _, f in _frames(tap, mark, "ctc>ixl")), 7.0)  # fmt: skip
    agree = _wait(lambda: lab.ctc_view()["summary"]["synced"] and lab.views_agree(), 5.0, 0.2)
    del full_before
    return ThreatResult("resequencing", "Type II IXL→CTC", "tap: reorder ixl>ctc (next two frames)",
                        "SEQ: gap → REQUEST_ALL; the late frame is dropped as old", asked,
                        "CTC view rebuilt by a full state, equal to the IXL's" if agree else
                        "CTC view differs from the IXL", agree,
                        [f"CTC REQUEST_ALL after the swap: {'yes' if asked else 'no'}"])  # fmt: skip


def corruption(lab: ThreatLab) -> ThreatResult:
    tap = lab.t1
    code = lab.atc_chart.number_of(lab.tcs[0])
    good = bytearray(FrameCodec(T1).encode_message(0x77, "CHANGE", items=[[code, 1], [code, 1]]))
    good[T1.header_size + 5] ^= 0x02  # one bit of the second item's state: still "occupied"
    mark = len(tap.records())
    tap.send("atc>ixl", bytes(good))
    nak = _wait(lambda: any(_name(f) == "NAK" and f.data[:1] == b"\x01"
                            for _, f in _frames(tap, mark, "ixl>atc")), 2.0)  # fmt: skip
    time.sleep(0.3)
    occupied = lab.ixl_status()["occupied"]
    safe = lab.tcs[0] not in occupied
    return ThreatResult("corruption", "Type I ATC→IXL", "tap: send atc>ixl (CHANGE with one bit flipped)",
                        "CRC: NAK reason 1, frame discarded", nak,
                        "nothing acted on: the track circuit the frame named is unchanged" if safe
                        else f"ACTED ON: {lab.tcs[0]} occupied", safe,
                        [f"IXL NAK reason 1: {'yes' if nak else 'no'}"])  # fmt: skip


def delay(lab: ThreatLab) -> ThreatResult:
    tap = lab.t2
    tap.inject(Delay(5.0, direction="ixl>ctc"))
    down = _wait(lambda: lab.ctc_view()["summary"]["link"] == "down", 8.0, 0.2)
    tap.clear()
    back = _wait(lambda: lab.ctc_view()["summary"]["synced"] and lab.views_agree(), 15.0, 0.25)
    ev = [
        f"CTC view of the station: {'down' if down else 'still up'} within 8 s",
        f"after clearing: {'reconnected and resynced' if back else 'not recovered'}",
    ]
    return ThreatResult("delay", "Type II IXL→CTC", "tap: delay 5 s ixl>ctc (past T_MAX 3 s)",
                        "timeout: T_MAX → connection closed, station shown link down", down,
                        "CTC showed the station down (no stale indications used); full resync "
                        "after the delay was removed" if down and back else "not fail-safe",
                        down and back, ev)  # fmt: skip


def masquerade(lab: ThreatLab) -> ThreatResult:
    tap = TcpTap(("127.0.0.1", 0), lab.ctc_address, names=("impostor", "ctc"), profile=T2)
    tap.start()
    lab.taps.append(tap)
    assert tap.listen_address is not None
    codec = FrameCodec(T2)
    before = lab.ctc_view()
    answers = []
    for station in (lab.station, 99):
        with socket.create_connection(tap.listen_address, timeout=3.0) as s:
            s.sendall(codec.encode_message(0, "IDENT", 0, station=station, version=1))
            s.settimeout(3.0)
            data = b""
            try:
                data = s.recv(4096)  # the answer to IDENT
                s.sendall(codec.encode_message(1, "INDICATION", 0, items=[[1, 1], [2, 1]]))
                while chunk := s.recv(4096):
                    data += chunk
            except (TimeoutError, ConnectionError, OSError):
                pass
        subs = [
            f.sub for f in StreamDecoder(T2).feed(data) if isinstance(f, Frame) and f.op == 0x01
        ]
        answers.append((station, subs))
    refused = all(subs == [2] for _, subs in answers)
    after = lab.ctc_view()
    same = after["state"] == before["state"] and after["summary"]["link"] == "up"
    logged = "refused 127.0.0.1:" in lab.ctc_log()
    ev = [f"IDENT station {st} → {'refused' if subs == [2] else subs}" for st, subs in answers]
    ev.append("CTC log names the impostor's address" if logged else "refusal not logged")
    return ThreatResult("masquerade", "Type II (impostor → CTC)",
                        "second tap: an impostor IDENTs as the connected station, then as station 99",
                        "IDENT/admission: station already connected / not configured", refused and logged,
                        "nothing acted on: the real station's view unchanged" if same
                        else "CTC view changed", same, ev)  # fmt: skip


THREATS: dict[str, Callable[[ThreatLab], ThreatResult]] = {
    "repetition": repetition,
    "deletion": deletion,
    "insertion": insertion,
    "resequencing": resequencing,
    "corruption": corruption,
    "delay": delay,
    "masquerade": masquerade,
}


def run_threats(lab: ThreatLab, names: list[str] | None = None) -> list[ThreatResult]:
    out = []
    for name in names or list(THREATS):
        _wait(lab.healthy, 10.0, 0.2)
        out.append(THREATS[name](lab))
    return out


def markdown(results: list[ThreatResult]) -> str:
    lines = ["| threat | link | injected through the tap | defence that caught it | caught | "
             "application outcome |", "|---|---|---|---|---|---|"]  # fmt: skip
    for r in results:
        lines.append(f"| {r.threat} | {r.link} | {r.injection} | {r.defence} | "
                     f"{'yes' if r.caught else 'NO'} | {r.outcome} |")  # fmt: skip
    return "\n".join(lines)
