"""The seven EN 50159 threats, each injected through the tap of a running link and judged twice:
on the wire (did the named defence react: SEQ, CRC, timeout, IDENT/admission) and in the
application (was anything acted on; fail-safe on loss), when the devices can be read.

A Type I target gets repetition, deletion, insertion and corruption aimed at its device under test
(the end that receives the injected frames; in a lab, the IXL). A Type II target gets resequencing,
delay and masquerade aimed at the CTC. Timings (T_MAX, heartbeat period, retry count) come from the
link's profile (`conformance.timing.SuiteTiming`), as the conformance suite judges them.
"""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

from ktcs_bench.codec import Frame, FrameCodec, FrameProfile, StreamDecoder
from ktcs_bench.conformance.timing import SuiteTiming
from ktcs_bench.errors import UsageError
from ktcs_bench.tap.tcp import TcpTap
from ktcs_bench.threats.application import Application
from ktcs_bench.threats.report import ThreatResult, not_run
from ktcs_bench.threats.wire import WireTap, wait_for

REPEAT_TRIES = 12  # repeat the peer's next frame until it is data, not an ACK (about half are)
UNKNOWN_STATION = 65000  # IDENT as a station no CTC configures
NOT_OBSERVED = "not observed (the device's state cannot be read: not one of our emulators)"


@dataclass
class ThreatTarget:
    """A tapped link under attack. `dut`: the tap end that receives the injected frames (Type I)
    or the CTC (Type II); `app`: its devices' state, when readable; `station` (Type II): the
    station the link carries, for the masquerade."""

    tap: WireTap
    dut: str
    app: Application
    station: int | None = None

    def __post_init__(self) -> None:
        if self.dut not in self.tap.names:
            raise UsageError(f"tap {self.tap.name} has ends {', '.join(self.tap.names)}, "
                             f"not {self.dut!r}")  # fmt: skip
        self.timing = SuiteTiming.resolve(self.tap.profile)

    @property
    def peer(self) -> str:
        a, b = self.tap.names
        return b if self.dut == a else a

    @property
    def toward(self) -> str:
        """The direction the injected frames travel: peer -> device under test."""
        return f"{self.peer}>{self.dut}"

    @property
    def back(self) -> str:
        return f"{self.dut}>{self.peer}"

    @property
    def link(self) -> str:
        kind = "Type I" if self.tap.protocol == "type1" else "Type II"
        return f"{kind} {self.tap.name} {self.peer}→{self.dut}"

    def op(self, f: Frame) -> str:
        return self.tap.op_name(f)

    def is_data(self, f: Frame) -> bool:
        return f.ok and self.op(f) not in ("ACK", "NAK")

    def data_seqs(self, since: int = 0) -> list[int]:
        return [f.seq for f in self.tap.frames(since, self.toward)
                if self.is_data(f) and f.seq is not None]  # fmt: skip

    def probe(self) -> tuple[int, int, str]:
        """A code the peer really sends, a false value for it (the opposite of the last value the
        wire carried; 1 if none was seen) and its name. The chart names it when known."""
        chart, name = self.app.rx_chart, self.app.probe
        code = chart.number_of(name) if chart is not None and name is not None else None
        last: int | None = None
        for f in reversed(self.tap.frames(0, self.toward)):
            opcode = self.tap.profile.opcodes.get(f.op) if f.op is not None else None
            if not (f.ok and opcode is not None and opcode.item_size):
                continue
            for c, v in reversed(opcode.items_of(f.data)):
                code = c if code is None else code
                if c == code:
                    last = int(v)
                    break
            if last is not None:
                break
        code = 1 if code is None else int(code)
        label = (chart.name_of(code) if chart is not None else None) or f"code {code}"
        return code, 0 if last else 1, label


def _outcome(app_ok: bool | None, good: str, bad: str, wire: str) -> tuple[str, bool | None]:
    if app_ok is None:
        return f"{NOT_OBSERVED}; on the wire: {wire}", None
    return (good if app_ok else bad), app_ok


# -- Type I ---------------------------------------------------------------------------------------
def repetition(t: ThreatTarget) -> ThreatResult:
    """The tap repeats the peer's next frame; when that is an ACK (not a delivery), again."""
    twice: Frame | None = None
    skipped = 0
    mark = t.tap.mark()
    # a slow machine or a quiet peer delays the frame; the repeat stays armed until it comes
    window = time.monotonic() + REPEAT_TRIES * (2 * t.timing.link_test_period + 2)
    while skipped < REPEAT_TRIES and time.monotonic() < window:
        mark = t.tap.act(f"duplicate 1 {t.toward}")
        pair: list[Frame] = []
        while len(pair) < 2 and time.monotonic() < window:
            pair = t.tap.next_frames(mark, t.toward, 2, 1.0)
        if len(pair) < 2:
            break
        if pair[0].raw == pair[1].raw and t.is_data(pair[0]):
            twice = pair[0]
            break
        skipped += 1
    time.sleep(0.5 + t.timing.ack_timeout)  # the ACK of the repeat
    back = t.tap.frames(mark, t.back)
    acks = [f for f in back if t.op(f) == "ACK" and twice is not None and f.seq == twice.seq]
    naks = [f for f in back if t.op(f) == "NAK"]
    resync = [f for f in back if t.op(f) == "REQUEST_ALL"]
    caught = twice is not None and len(acks) >= 2 and not naks and not resync
    status = t.app.ixl_status()
    app_ok = None if status is None else t.app.settled(status)
    outcome, safe = _outcome(app_ok, "link stays up, the IXL's state unchanged",
                             f"the IXL's state changed: {status}", "ACKed twice, no resync")  # fmt: skip
    ev = [f"{t.op(twice)} SEQ 0x{twice.seq:02X} delivered twice by the tap" if twice and twice.seq
          is not None else "no frame was repeated", f"ACKs of that SEQ: {len(acks)}, NAKs: "
          f"{len(naks)}, REQUEST_ALL: {len(resync)}"]  # fmt: skip
    if skipped:
        ev.insert(0, f"{skipped} repeated frame(s) before it were ACK/NAK, not deliveries")
    return ThreatResult("repetition", t.link, f"tap: duplicate 1 {t.toward}",
                        "SEQ: the repeat of the last accepted SEQ is ACKed, not delivered", caught,
                        outcome, safe, ev)  # fmt: skip


def deletion(t: ThreatTarget) -> ThreatResult:
    before = t.data_seqs()
    mark = t.tap.act(f"drop-frame 1 {t.toward}")
    time.sleep(2 * t.timing.link_test_period + 0.5)  # a LINK_TEST or an ACK is due by then
    dut_data = [f.raw for f in t.tap.frames(mark, t.back) if t.is_data(f)]
    after = t.data_seqs(mark)
    resync = any(t.op(f) == "REQUEST_ALL" for f in t.tap.frames(mark, t.back))
    if len(dut_data) != len(set(dut_data)):
        retx, how = True, f"an ACK was lost: {t.dut} retransmitted its frame with the same SEQ"
    elif before and after and after[0] == (before[-1] + 1) % 256 and not resync:
        retx = True
        how = (f"a frame of {t.peer} was lost: SEQ 0x{after[0]:02X} arrived after the ACK "
               f"timeout (retransmitted), no SEQ gap at {t.dut}")  # fmt: skip
    else:
        retx, how = False, "no retransmission seen"
    ev = [f"one frame dropped; {how}"]
    # Sustained loss: cut the peer's direction past T_MAX; the device under test must go fail-safe.
    t.tap.act(f"cut {t.toward}")
    limit = t.timing.t_max + t.timing.tolerance + 4.0
    if t.app.readable:
        down = wait_for(lambda: t.app.link_up() is False, limit, 0.2)
        status = t.app.ixl_status()
        failsafe: bool | None = status is not None and t.app.failsafe(status)
        ev.append(f"cut {t.toward}: the IXL's {t.app.role} link "
                  f"{'down' if down else 'still up'}; fail-safe state: "
                  f"{'yes' if failsafe else 'no'}")  # fmt: skip
    else:
        time.sleep(limit)
        down, failsafe = True, None
        ev.append(f"cut {t.toward} for {limit:.1f} s (T_MAX {t.timing.t_max:g} s)")
    restored = t.tap.act(f"restore {t.toward}")
    asked = t.tap.wait_frame(restored, t.back, lambda f: t.op(f) == "REQUEST_ALL", 10.0)
    answered = t.tap.wait_frame(restored, t.toward, lambda f: t.op(f) == "ALL_INFO", 10.0)
    back: bool | None = None
    if t.app.readable:
        back = wait_for(lambda: t.app.settled(t.app.ixl_status() or {}), 10.0, 0.2)
    ev.append(f"restored: {t.dut} REQUEST_ALL {'sent' if asked else 'NOT sent'}, {t.peer} "
              f"ALL_INFO {'sent' if answered else 'not seen'}")  # fmt: skip
    app_ok = None if failsafe is None else bool(failsafe and back)
    outcome, safe = _outcome(app_ok, f"fail-safe: the IXL took its {t.app.role} inputs as unsafe "
                             "while the link was lost, and rebuilt them on recovery",
                             "NOT fail-safe", "state rebuilt by REQUEST_ALL → ALL_INFO after the "
                             "outage" if asked and answered else "no resync after the outage")  # fmt: skip
    return ThreatResult("deletion", t.link, f"tap: drop-frame 1 {t.toward}; cut {t.toward}",
                        "timeout: ACK timeout → retransmission; T_MAX silence → link down",
                        retx and down and asked, outcome, safe, ev)  # fmt: skip


def insertion(t: ThreatTarget) -> ThreatResult:
    seqs = t.data_seqs()
    seq = ((seqs[-1] if seqs else 0) + 100) % 256
    code, value, label = t.probe()
    frame = FrameCodec(t.tap.profile).encode_message(seq, "CHANGE", items=[[code, value]])
    before = t.app.inputs()
    mark = t.tap.act(f"send {t.toward} {frame.hex()}")
    asked = t.tap.wait_frame(mark, t.back, lambda f: t.op(f) == "REQUEST_ALL", 3.0)
    answered = t.tap.wait_frame(mark, t.toward, lambda f: t.op(f) == "ALL_INFO", 5.0)
    app_ok: bool | None = None
    if before is not None:
        app_ok = wait_for(lambda: t.app.inputs() == before, 3.0)
    ev = [f"inserted CHANGE {label}={value} (false) with SEQ 0x{seq:02X} (out of sequence)",
          f"{t.dut}: SEQ gap → REQUEST_ALL {'sent' if asked else 'NOT sent'}; {t.peer} ALL_INFO "
          f"{'sent' if answered else 'not seen'}"]  # fmt: skip
    outcome, safe = _outcome(app_ok, "inserted value replaced by the true state within one "
                             "exchange (Type I has no source authentication: until then the "
                             "IXL may act on it)", "inserted value persists",
                             "the full state was asked for and sent")  # fmt: skip
    return ThreatResult("insertion", t.link, f"tap: send {t.toward} (a well-formed CHANGE)",
                        "SEQ: gap → REQUEST_ALL, state rebuilt from the sender's ALL_INFO",
                        asked and answered, outcome, safe, ev)  # fmt: skip


def corrupted_change(profile: FrameProfile, seq: int, code: int, value: int) -> bytes:
    """A CHANGE of two items `code`=`value` with one bit of the second item's state flipped after
    its CRC was computed: where that bit sits is read off the profile (header, fixed fields, the
    items' width and the state's place in one)."""
    opcode = profile.opcodes.by_name["CHANGE"]
    frame = bytearray(FrameCodec(profile).encode_message(seq, "CHANGE",
                                                         items=[[code, value], [code, value]]))  # fmt: skip
    names = [f.name for f in opcode.items]
    k = names.index("state")
    state = sum(f.size for f in opcode.items[:k])  # its place in an item
    low = 0 if profile.little else opcode.items[k].size - 1  # its least significant byte
    at = profile.header_size + opcode.fixed_size + opcode.item_size + state + low
    frame[at] ^= 0x02
    return bytes(frame)


def corruption(t: ThreatTarget) -> ThreatResult:
    profile = t.tap.profile
    code, value, _ = t.probe()
    frame = corrupted_change(profile, 0x77, code, value)
    crc_nak = bytes([profile.nak_reason("crc error")])
    before = t.app.inputs()
    mark = t.tap.act(f"send {t.toward} {frame.hex()}")
    nak = t.tap.wait_frame(mark, t.back, lambda f: t.op(f) == "NAK" and f.data[:1] == crc_nak, 2.0)
    time.sleep(0.3)
    acked = [f for f in t.tap.frames(mark, t.back) if t.op(f) == "ACK" and f.seq == 0x77]
    app_ok = None if before is None else t.app.inputs() == before
    outcome, safe = _outcome(app_ok, "nothing acted on: the IXL's inputs are unchanged",
                             "ACTED ON: the corrupted value was taken", "NAKed, not ACKed")  # fmt: skip
    return ThreatResult("corruption", t.link, f"tap: send {t.toward} (CHANGE, one bit flipped)",
                        f"CRC: NAK reason {crc_nak[0]}, frame discarded", nak and not acked,
                        outcome, safe,
                        [f"{t.dut} NAK reason {crc_nak[0]}: {'yes' if nak else 'no'}; ACK of its SEQ: "
                         f"{'yes' if acked else 'no'}"])  # fmt: skip


# -- Type II --------------------------------------------------------------------------------------
def _synced(t: ThreatTarget) -> bool | None:
    return t.app.views_agree() if t.app.ctc is not None else None


def resequencing(t: ThreatTarget) -> ThreatResult:
    mark = t.tap.act(f"reorder {t.toward}")
    asked = t.tap.wait_frame(mark, t.back, lambda f: f.ok and t.op(f) == "REQUEST_ALL",
                             2 * t.timing.heartbeat_period + 3.0)  # fmt: skip
    dumped = t.tap.wait_frame(mark, t.toward, lambda f: t.op(f) == "INDICATION" and f.sub == 2, 5.0)
    app_ok = None
    if t.app.ctc is not None:
        app_ok = wait_for(lambda: bool(_synced(t)), 5.0, 0.2)
    outcome, safe = _outcome(app_ok, "the CTC's view rebuilt by a full state, equal to the IXL's",
                             "the CTC's view differs from the IXL", "a full state followed the "
                             "REQUEST_ALL" if dumped else "no full state seen")  # fmt: skip
    return ThreatResult("resequencing", t.link, f"tap: reorder {t.toward} (next two frames)",
                        "SEQ: gap → REQUEST_ALL; the late frame is dropped as old", asked, outcome,
                        safe, [f"{t.dut} REQUEST_ALL after the swap: {'yes' if asked else 'no'}; "
                               f"full state sent: {'yes' if dumped else 'no'}"])  # fmt: skip


def delay(t: ThreatTarget) -> ThreatResult:
    hold = t.timing.t2_t_max + 2.0
    mark = t.tap.act(f"delay {hold:g} {t.toward}")
    limit = t.timing.t2_t_max + t.timing.tolerance + 4.0
    closed = wait_for(lambda: bool(t.tap.events(mark, "disconnected")), limit, 0.1)
    shown_down = None
    if t.app.ctc is not None:
        shown_down = wait_for(lambda: (t.app.ctc_view() or {})["summary"]["link"] == "down", 2.0)
    cleared = t.tap.act("clear")
    again = wait_for(lambda: bool(t.tap.events(cleared, "connected")), 15.0, 0.1)
    app_ok = None
    if t.app.ctc is not None:
        app_ok = bool(shown_down) and wait_for(lambda: bool(_synced(t)), 15.0, 0.25)
    why = [e.get("reason", "") for e in t.tap.events(mark, "disconnected")][:1]
    ev = [f"connection closed within {limit:.1f} s: {'yes (' + why[0] + ')' if closed else 'no'}",
          f"after clearing: {'reconnected' if again else 'not reconnected'}"]  # fmt: skip
    if shown_down is not None:
        ev.append(f"the CTC showed the station {'down' if shown_down else 'still up'}")
    outcome, safe = _outcome(app_ok, "the CTC showed the station down (no stale indications "
                             "used); full resync after the delay was removed", "not fail-safe",
                             "the stale connection was dropped and a new one made")  # fmt: skip
    return ThreatResult("delay", t.link, f"tap: delay {hold:g} s {t.toward} (past T_MAX "
                        f"{t.timing.t2_t_max:g} s)", "timeout: T_MAX → connection closed, station "
                        "shown link down", closed and again, outcome, safe, ev)  # fmt: skip


def _connected_station(t: ThreatTarget) -> int | None:
    if t.station is not None:
        return t.station
    opcode = t.tap.profile.opcodes.by_name.get("IDENT")
    for f in t.tap.frames(0, t.toward):
        if opcode is not None and f.ok and f.op == opcode.op and f.sub == 0:
            return int(opcode.parse(f.data)["station"])
    return t.app.station


def _impostor(address: tuple[str, int], codec: FrameCodec, station: int) -> list[int | None]:
    """IDENT as `station`, then push an INDICATION; the IDENT answers' SUBs (2: refused)."""
    data = b""
    with socket.create_connection(address, timeout=3.0) as s:
        s.sendall(codec.encode_message(0, "IDENT", 0, station=station, version=1))
        try:
            data = s.recv(4096)
            s.sendall(codec.encode_message(1, "INDICATION", 0, items=[[1, 1], [2, 1]]))
            while chunk := s.recv(4096):
                data += chunk
        except OSError:
            pass
    ident = codec.profile.opcodes.by_name["IDENT"].op
    return [f.sub for f in StreamDecoder(codec.profile).feed(data)
            if isinstance(f, Frame) and f.op == ident]  # fmt: skip


def masquerade(t: ThreatTarget) -> ThreatResult:
    station = _connected_station(t)
    target = t.tap.info.get("target")
    if t.tap.kind != "tcp" or not target:
        return not_run("masquerade", f"not run: needs a TCP tap in front of the CTC; "
                       f"{t.tap.name} is a {t.tap.kind} tap")  # fmt: skip
    if station is None:
        return not_run("masquerade", f"not run: no IDENT on {t.tap.name}'s record to learn the "
                       "connected station from; give --station")  # fmt: skip
    address = (str(target[0]), int(target[1]))
    before = t.app.ctc_view()
    mark = t.tap.mark()
    imp = TcpTap(("127.0.0.1", 0), address, names=("impostor", t.dut), profile=t.tap.profile)
    imp.start()
    try:
        assert imp.listen_address is not None
        codec = FrameCodec(t.tap.profile)
        answers = [(st, _impostor(imp.listen_address, codec, st))
                   for st in (station, UNKNOWN_STATION)]  # fmt: skip
    finally:
        imp.stop()
    refused = all(subs == [2] for _, subs in answers)
    kept = not t.tap.events(mark, "disconnected")
    log = t.app.ctc_log_text()
    logged = None if log is None else "refused 127.0.0.1:" in log
    ev = [f"IDENT station {st} → {'refused' if subs == [2] else subs or 'no answer'}"
          for st, subs in answers]  # fmt: skip
    ev.append(f"the real station's connection {'kept' if kept else 'DROPPED'}")
    if logged is not None:
        ev.append("the CTC's log names the impostor's address" if logged else "refusal not logged")
    app_ok = None
    if before is not None:
        after = t.app.ctc_view() or {}
        app_ok = after.get("state") == before["state"] and after["summary"]["link"] == "up"
    outcome, safe = _outcome(app_ok, "nothing acted on: the real station's view unchanged",
                             "the CTC's view changed", "refused at IDENT, the real connection "
                             "kept" if kept else "the real connection dropped")  # fmt: skip
    return ThreatResult("masquerade", f"Type II impostor→{t.dut} (beside {t.tap.name})",
                        f"a second tap in front of the CTC: IDENT as station {station} (connected) "
                        f"and as {UNKNOWN_STATION} (not configured)",
                        "IDENT/admission: station already connected / not configured",
                        refused and kept and logged is not False, outcome, safe, ev)  # fmt: skip


def settle(t: ThreatTarget, timeout: float = 15.0) -> bool:
    """Wait until the link is healthy again before the next threat: the devices' state when it can
    be read, else traffic seen both ways."""
    if t.tap.protocol == "type2" and t.app.ctc is not None:
        return wait_for(lambda: bool(_synced(t)), timeout, 0.2)
    if t.tap.protocol == "type1" and t.app.readable:
        return wait_for(lambda: t.app.settled(t.app.ixl_status() or {}), timeout, 0.2)
    if t.tap.protocol == "type2":
        return wait_for(lambda: _steady(t), timeout, 0.0)
    mark = t.tap.mark()
    return wait_for(lambda: bool(t.tap.frames(mark, t.toward) and t.tap.frames(mark, t.back)),
                    timeout)  # fmt: skip


def _steady(t: ThreatTarget) -> bool:
    """Type II seen from the wire alone: one connection, traffic both ways and no connect or
    disconnect for two heartbeat periods (a reconnecting station is not yet a target)."""
    mark = t.tap.mark()
    time.sleep(2 * t.timing.heartbeat_period + 0.2)
    churn = t.tap.events(mark, "connected") or t.tap.events(mark, "disconnected")
    traffic = t.tap.frames(mark, t.toward) and t.tap.frames(mark, t.back)
    return bool(traffic and not churn and t.tap.status().get("connected"))


ThreatFn = Callable[[ThreatTarget], ThreatResult]
THREATS: dict[str, tuple[str, ThreatFn]] = {
    "repetition": ("type1", repetition),
    "deletion": ("type1", deletion),
    "insertion": ("type1", insertion),
    "resequencing": ("type2", resequencing),
    "corruption": ("type1", corruption),
    "delay": ("type2", delay),
    "masquerade": ("type2", masquerade),
}


def run_campaign(
    targets: list[ThreatTarget],
    names: list[str] | None = None,
    before_each: Callable[[ThreatTarget], object] = settle,
    progress: Callable[[str], None] | None = None,
) -> list[ThreatResult]:
    """Each chosen threat against the first target of its protocol; a threat with no such target
    is reported as not run. `before_each` waits for the link to be healthy again."""
    out = []
    for name in names or list(THREATS):
        protocol, fn = THREATS[name]
        target = next((t for t in targets if t.tap.protocol == protocol), None)
        if target is None:
            kind = "Type I" if protocol == "type1" else "Type II"
            out.append(not_run(name, f"not run: needs a {kind} target"))
            continue
        if progress is not None:
            progress(f"{name} on {target.tap.name} ...")
        before_each(target)
        try:
            out.append(fn(target))
        except BaseException:
            _clear(target)  # Ctrl-C or a lost device mid-threat: never leave a link cut or delayed
            raise
    return out


def _clear(t: ThreatTarget) -> None:
    with contextlib.suppress(Exception):
        t.tap.act("clear", timeout=2.0)
