"""Fault variants: emulators that break exactly one protocol rule on purpose, so the conformance
suite can show it catches each (`ktcs-bench emulator KIND --fault VARIANT`).

`FAULTS` names every variant, the rule it breaks and the conformance case that must catch it.
`type1_link()` builds the Type I link a device's code port uses; `ixl_client()` and
`ctc_server()` build the Type II ends -- each with the variant's behaviour when one is selected.
The correct behaviour lives in `type1/` and `type2/`; a variant is a small subclass here.
"""

from __future__ import annotations

import dataclasses
import ssl as ssl_module
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.codec import FrameCodec
from ktcs_bench.codec.profile import FrameProfile
from ktcs_bench.errors import UsageError
from ktcs_bench.transport.ctc_server import CtcApplication, CtcServer
from ktcs_bench.transport.ixl_client import IxlApplication, IxlClient
from ktcs_bench.type1 import LinkConfig, StateProvider, Type1Link
from ktcs_bench.type1.arq import Acceptance, Receiver
from ktcs_bench.type1.events import LinkEvent
from ktcs_bench.type1.link import NAK_FORMAT
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.admission import ADMIT, AdmissionPolicy, Decision
from ktcs_bench.type2.ixl_side import IxlSession


@dataclass(frozen=True)
class Variant:
    kind: str  # which devices it applies to: "type1" (atc, ixl, trackside), "ixl", "ctc"
    breaks: str
    caught_by: str


FAULTS: dict[str, Variant] = {
    "no-retransmit": Variant("type1", "never retransmits: no ACK or a NAK ends the frame at once",
                             "ack-timeout-retransmission"),
    "extra-retransmit": Variant("type1", "retransmits 4 times instead of 3 before giving up",
                                "retry-limit"),
    "crc-byte-order": Variant("type1", "sends its CRC high byte first", "framing"),
    "no-nak": Variant("type1", "never sends NAK (bad frames are dropped silently)",
                      "crc-error-nak"),
    "wrong-nak-reason": Variant("type1", "NAKs every bad frame with reason 3", "crc-error-nak"),
    "no-delta-r": Variant("type1", "never times out an incomplete frame (no ΔR)", "delta-r-nak"),
    "duplicate-delivery": Variant("type1", "delivers a repeated SEQ again", "duplicate-seq"),
    "short-all-info": Variant("type1", "ALL_INFO leaves out the chart's last code", "request-all"),
    "no-link-test": Variant("type1", "never sends LINK_TEST when idle", "link-test-timing"),
    "dump-out-of-order": Variant(kinds.IXL, "Type II full state not in chart order", "t2-full-dump"),
    "ignore-nak": Variant(kinds.IXL, "Type II: ignores NAK (no retransmission)",
                          "t2-nak-retransmission"),
    "no-heartbeat": Variant(kinds.IXL, "Type II: sends no HEARTBEAT when idle", "t2-heartbeat"),
    "accept-unknown-station": Variant(kinds.CTC, "admits a station not in its lab",
                                      "t2-refused-station"),
}  # fmt: skip


def check(names: Iterable[str], kind: str | None = None) -> frozenset[str]:
    chosen = frozenset(names)
    unknown = sorted(chosen - FAULTS.keys())
    if unknown:
        known = ", ".join(sorted(FAULTS)) or "none yet"
        raise UsageError(f"unknown fault variant(s) {', '.join(unknown)} (known: {known})")
    if kind is not None:
        applies = {kinds.CTC: (kinds.CTC,), kinds.IXL: (kinds.IXL, "type1")}.get(kind, ("type1",))
        wrong = sorted(n for n in chosen if FAULTS[n].kind not in applies)
        if wrong:
            raise UsageError(f"fault variant(s) {', '.join(wrong)} do not apply to {kind}")
    return chosen


# -- Type I ---------------------------------------------------------------------------------------
class _SwappedCrcCodec(FrameCodec):
    """Encodes frames with the CRC bytes in the wrong order."""

    def encode(self, seq: int, op: int, data: bytes = b"", sub: int | None = None) -> bytes:
        frame = bytearray(super().encode(seq, op, data, sub))
        p = self.profile
        at = p.header_size + len(data)
        frame[at : at + p.crc_size] = frame[at : at + p.crc_size][::-1]
        return bytes(frame)


class _ForgetfulReceiver(Receiver):
    def accept(self, seq: int, now: float) -> Acceptance:
        self.last_seq = None
        return super().accept(seq, now)


class _VariantLink(Type1Link):
    def __init__(self, faults: frozenset[str], *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.faults = faults
        if "crc-byte-order" in faults:
            self._codec = _SwappedCrcCodec(self.profile)
        if "duplicate-delivery" in faults:
            self._receiver = _ForgetfulReceiver(self._codec.seq_modulo)

    def _nak(self, seq: int, reason: str, detail: str, raw: bytes, events: list[LinkEvent]) -> None:
        if "no-nak" in self.faults:
            return
        if "wrong-nak-reason" in self.faults:
            reason = NAK_FORMAT  # whatever was wrong, a length/format error
        super()._nak(seq, reason, detail, raw, events)

    def handle_timer(self, now: float) -> list[LinkEvent]:
        if "no-delta-r" in self.faults:
            self._rx_pending_since = None
        return super().handle_timer(now)

    @property
    def _idle(self) -> bool:
        if "no-link-test" in self.faults:
            return False
        return self._sender.idle and not self._control


def type1_link(
    faults: frozenset[str],
    profile: FrameProfile | str,
    config: LinkConfig | None,
    name: str,
    state_provider: StateProvider | None,
) -> Type1Link:
    mine = faults & {n for n, v in FAULTS.items() if v.kind == "type1"}
    if not mine:
        return Type1Link(profile, config, name, state_provider=state_provider)
    cfg = config if config is not None else LinkConfig()
    if "no-retransmit" in mine:
        cfg = dataclasses.replace(cfg, max_retransmissions=0)
    if "extra-retransmit" in mine:
        cfg = dataclasses.replace(cfg, max_retransmissions=cfg.max_retransmissions + 1)
    provider = state_provider
    if "short-all-info" in mine and state_provider is not None:
        inner = state_provider

        def provider(start: int, count: int) -> bytes | Sequence[int]:
            return bytes(inner(start, count))[:-1]

    return _VariantLink(mine, profile, cfg, name, state_provider=provider)


# -- Type II, IXL side ----------------------------------------------------------------------------
class _VariantIxlSession(IxlSession):
    faults: frozenset[str] = frozenset()

    def send_full_state(self, items: Iterable[tuple[int, int]], now: float) -> int:
        if "dump-out-of-order" not in self.faults:
            return super().send_full_state(items, now)
        self._check_open()
        chunk = sorted(self._as_items(items), reverse=True)
        return self._send_items(self.op_indication, chunk, (1, 2), now)

    def _on_nak(self, frame: Any, now: float) -> None:
        if "ignore-nak" in self.faults:
            if len(frame.data) == 1:
                self._events.append(ev.NakReceived(frame.data[0], frame.sub or 0))
            return
        super()._on_nak(frame, now)

    def handle_timer(self, now: float) -> list[ev.SessionEvent]:
        if "no-heartbeat" in self.faults:
            self._last_tx = now
        return super().handle_timer(now)


def ixl_client(
    faults: frozenset[str],
    station: int,
    host: str,
    port: int,
    app: IxlApplication,
    *,
    ssl: ssl_module.SSLContext | None = None,
    server_hostname: str | None = None,
) -> IxlClient:
    mine = faults & {n for n, v in FAULTS.items() if v.kind == kinds.IXL}
    client = IxlClient(station, host, port, app, ssl=ssl, server_hostname=server_hostname)
    if mine:
        session_class = type("FaultyIxlSession", (_VariantIxlSession,), {"faults": mine})
        client.session_class = session_class
    return client


# -- Type II, CTC side ----------------------------------------------------------------------------
class _OpenPolicy(AdmissionPolicy):
    def check_ident(self, station: int, version: int, host: str, connected: Any) -> Decision:
        decision = super().check_ident(station, version, host, connected)
        if not decision and station not in self.stations:
            return ADMIT
        return decision


def ctc_server(
    faults: frozenset[str],
    stations: Iterable[int],
    app: CtcApplication,
    *,
    allowed_sources: Iterable[str] | None,
    host: str,
    port: int,
    ssl: ssl_module.SSLContext | None = None,
) -> CtcServer:
    if "accept-unknown-station" in faults:
        policy: AdmissionPolicy = _OpenPolicy(stations, allowed_sources=allowed_sources)
    else:
        policy = AdmissionPolicy(stations, allowed_sources=allowed_sources)
    return CtcServer(policy, app, host=host, port=port, ssl=ssl)
