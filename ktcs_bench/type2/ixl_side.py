"""The IXL end of a Type II link (the TCP client), sans-I/O.

Opens with IDENT; once the CTC accepts, the adapter sends the full state (`send_full_state`), then
change indications as objects change. It answers CONTROL with CONTROL_RESULT and REQUEST_ALL with a
new full state -- both announced as events, because the state and the interlocking logic belong to
the caller, not to the link.
"""

from __future__ import annotations

from collections.abc import Iterable

from ktcs_bench import kinds
from ktcs_bench.codec import Frame
from ktcs_bench.errors import UsageError
from ktcs_bench.type2 import events as ev
from ktcs_bench.type2.config import Type2Config
from ktcs_bench.type2.session import (
    NAK_FORMAT,
    OP_CONTROL,
    OP_CONTROL_RESULT,
    OP_IDENT,
    OP_REQUEST_ALL,
    SUB_ACCEPTED,
    SUB_CHANGE,
    SUB_FULL_LAST,
    SUB_FULL_PART,
    SUB_IDENT_ACCEPTED,
    SUB_IDENT_REFUSED,
    SUB_IDENT_REQUEST,
    SUB_REJECTED,
    FrameRefused,
    SessionState,
    Type2Session,
)


class IxlSession(Type2Session):
    """One connection of station `station`'s IXL to the CTC. IDENT is queued at construction."""

    role = kinds.IXL

    def __init__(self, station: int, now: float, config: Type2Config | None = None) -> None:
        super().__init__(now, config)
        if not 0 <= station <= 0xFFFF:
            raise UsageError(f"station number {station} does not fit u16")
        self.station = station
        self._handlers[OP_IDENT] = self._on_ident
        self._handlers[OP_CONTROL] = self._on_control
        self._handlers[OP_REQUEST_ALL] = self._on_request_all
        data = self.op_ident.build({"station": station, "version": self.config.version})
        self._send(OP_IDENT, SUB_IDENT_REQUEST, data, now)

    # -- what the IXL sends --------------------------------------------------------------------
    def send_full_state(self, items: Iterable[tuple[int, int]], now: float) -> int:
        """Every code's state, in chart order, in parts of <= 40 (sub 1; sub 2 for the last part).

        Returns the number of frames. Items are sorted by code number (= chart position).
        """
        self._check_open()
        chunk = sorted(self._as_items(items))
        return self._send_items(self.op_indication, chunk, (SUB_FULL_PART, SUB_FULL_LAST), now)

    def send_indications(self, items: Iterable[tuple[int, int]], now: float) -> int:
        """Change indications (sub 0), several codes per message, order kept. Returns frames sent."""
        self._check_open()
        changes = self._as_items(items)
        if not changes:
            return 0
        return self._send_items(self.op_indication, changes, (SUB_CHANGE, SUB_CHANGE), now)

    def send_control_result(self, code: int, accepted: bool, reason: int, now: float) -> None:
        """Answer one control code: accepted (reason 0) or rejected with a reason from type2.yaml."""
        self._check_open()
        data = self.op_result.build({"code": code, "reason": 0 if accepted else reason})
        self._send(OP_CONTROL_RESULT, SUB_ACCEPTED if accepted else SUB_REJECTED, data, now)

    def _check_open(self) -> None:
        if self.state is not SessionState.OPEN:
            raise UsageError(f"Type II IXL session is {self.state.value}, not open")

    # -- what the IXL receives -----------------------------------------------------------------
    def _on_ident(self, frame: Frame, now: float) -> None:
        sub = self._expect_sub(frame, SUB_IDENT_ACCEPTED, SUB_IDENT_REFUSED)
        fields = self.op_ident.parse(frame.data)
        if self.state is not SessionState.IDENTIFYING:
            raise FrameRefused(NAK_FORMAT, "IDENT answer on an open connection")
        if fields["station"] != self.station:
            raise FrameRefused(NAK_FORMAT, f"IDENT answer names station {fields['station']}")
        if sub == SUB_IDENT_ACCEPTED:
            self.state = SessionState.OPEN
            self._events.append(ev.IdentAccepted(self.station))
        else:
            self._events.append(ev.IdentRefused(self.station))
            self._close(f"station {self.station} refused by the CTC")

    def _on_control(self, frame: Frame, now: float) -> None:
        self._expect_sub(frame, 0)
        items = self._items(self.op_control, frame)
        self._require_open(frame)
        self._events.append(ev.ControlRequested(items))

    def _on_request_all(self, frame: Frame, now: float) -> None:
        self._expect_sub(frame, 0)
        self._expect_empty(frame)
        self._require_open(frame)
        self._events.append(ev.FullStateRequested())


__all__ = ["IxlSession"]
