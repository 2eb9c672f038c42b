"""The CTC end of one Type II connection (the server side), sans-I/O.

Waits for IDENT and reports it (`IdentRequested`); the server's admission policy then calls
`accept()` or `refuse()`. Afterwards it reports change indications, complete full-state dumps and
control results, sends CONTROL and REQUEST_ALL, and asks REQUEST_ALL by itself on a SEQ gap.
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
    OP_CONTROL_RESULT,
    OP_IDENT,
    OP_INDICATION,
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


class CtcConnection(Type2Session):
    """One accepted TCP connection at the CTC, before and after its IXL has identified."""

    role = kinds.CTC

    def __init__(self, now: float, config: Type2Config | None = None) -> None:
        super().__init__(now, config)
        self.station: int | None = None  # known once IDENT arrived
        self.peer_version: int | None = None
        self.resync_pending = False  # a full state is owed (after accept or REQUEST_ALL)
        self._staging: dict[int, int] = {}
        self._parts = 0
        self._handlers[OP_IDENT] = self._on_ident
        self._handlers[OP_INDICATION] = self._on_indication
        self._handlers[OP_CONTROL_RESULT] = self._on_result

    # -- the server's answers and commands -----------------------------------------------------
    def accept(self, now: float) -> None:
        """Admit the station named in IDENT; its full state follows."""
        self._check_ident_pending()
        assert self.station is not None
        data = self.op_ident.build({"station": self.station, "version": self.config.version})
        self._send(OP_IDENT, SUB_IDENT_ACCEPTED, data, now)
        self.state = SessionState.OPEN
        self.resync_pending = True

    def refuse(self, now: float, reason: str) -> list[ev.SessionEvent]:
        """Refuse the station (IDENT sub 2) and close; `reason` is for the log, not the wire."""
        self._check_ident_pending()
        assert self.station is not None
        data = self.op_ident.build({"station": self.station, "version": self.config.version})
        self._send(OP_IDENT, SUB_IDENT_REFUSED, data, now)
        return self.close(f"refused: {reason}")

    def send_control(self, items: Iterable[tuple[int, int]], now: float) -> int:
        """CONTROL items (control code, value), <= 40 per message. Returns frames sent."""
        self._check_open()
        controls = self._as_items(items)
        if not controls:
            return 0
        return self._send_items(self.op_control, controls, (0, 0), now)

    def request_all(self, now: float) -> None:
        """Ask the IXL for its full state (REQUEST_ALL)."""
        self._check_open()
        self._send(OP_REQUEST_ALL, 0, b"", now)
        self.resync_pending = True

    def _check_open(self) -> None:
        if self.state is not SessionState.OPEN:
            raise UsageError(f"Type II CTC connection is {self.state.value}, not open")

    def _check_ident_pending(self) -> None:
        if self.state is not SessionState.IDENTIFYING or self.station is None:
            raise UsageError("no IDENT is waiting for an answer")

    def _on_gap(self, now: float) -> None:
        if self.state is SessionState.OPEN and not self.resync_pending:
            self.request_all(now)

    # -- what the CTC receives -----------------------------------------------------------------
    def _on_ident(self, frame: Frame, now: float) -> None:
        self._expect_sub(frame, SUB_IDENT_REQUEST)
        fields = self.op_ident.parse(frame.data)
        if self.station is not None:
            raise FrameRefused(NAK_FORMAT, "IDENT repeated on this connection")
        self.station = int(fields["station"])
        self.peer_version = int(fields["version"])
        self._events.append(ev.IdentRequested(self.station, self.peer_version))

    def _on_indication(self, frame: Frame, now: float) -> None:
        sub = self._expect_sub(frame, SUB_CHANGE, SUB_FULL_PART, SUB_FULL_LAST)
        items = self._items(self.op_indication, frame)
        self._require_open(frame)
        if sub == SUB_CHANGE:
            self._events.append(ev.IndicationsChanged(items))
            return
        self._staging.update(items)
        self._parts += 1
        if sub == SUB_FULL_LAST:
            full = tuple(sorted(self._staging.items()))
            self._events.append(ev.FullState(full, self._parts))
            self._staging = {}
            self._parts = 0
            self.resync_pending = False

    def _on_result(self, frame: Frame, now: float) -> None:
        sub = self._expect_sub(frame, SUB_ACCEPTED, SUB_REJECTED)
        fields = self.op_result.parse(frame.data)
        self._require_open(frame)
        reason = int(fields["reason"])
        name = self.op_result.reasons.get(reason, f"reason {reason}")
        self._events.append(
            ev.ControlAnswered(int(fields["code"]), sub == SUB_ACCEPTED, reason, name)
        )


__all__ = ["CtcConnection"]
