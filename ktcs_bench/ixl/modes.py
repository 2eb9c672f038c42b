"""Center/local mode and the CMR handshake (seed 004 Table 3: LOC, CTC, CMR).

The station starts in local mode. The CTC asks for center mode (control CMQ); the IXL raises CMR
("center mode requested") and waits for the local operator to grant or refuse; on a grant the
station goes to center mode (CTC=1, LOC=0, CMR=0). A lab without a local operator may set
`auto_grant_s`: the request is then granted that many seconds after it arrived, so the handshake
is still visible on the wire. The CTC hands control back with LMQ; the local operator can take
the station back at any time.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Mode(Enum):
    LOCAL = "local"
    CENTER = "center"


@dataclass
class ModeControl:
    mode: Mode = Mode.LOCAL
    auto_grant_s: float | None = None
    requested_at: float | None = None  # CMR is 1 while this is set

    @property
    def requested(self) -> bool:
        return self.requested_at is not None

    def request_center(self, now: float) -> bool:
        """CTC asks for center mode; True when a new request is now pending."""
        if self.mode is Mode.CENTER or self.requested_at is not None:
            return False
        self.requested_at = now
        return True

    def grant(self) -> bool:
        if self.requested_at is None:
            return False
        self.requested_at = None
        self.mode = Mode.CENTER
        return True

    def refuse(self) -> bool:
        pending = self.requested_at is not None
        self.requested_at = None
        return pending

    def to_local(self) -> bool:
        changed = self.mode is Mode.CENTER or self.requested_at is not None
        self.mode = Mode.LOCAL
        self.requested_at = None
        return changed

    def next_deadline(self) -> float | None:
        if self.requested_at is None or self.auto_grant_s is None:
            return None
        return self.requested_at + self.auto_grant_s

    def handle_timer(self, now: float) -> bool:
        """Apply the automatic grant when due; True when the mode changed."""
        due = self.next_deadline()
        if due is not None and now >= due:
            return self.grant()
        return False
