"""One way to operate a lab, whichever clock it runs on: `LabAccess`.

A lab runs live (a process per device, `lab up`, the wall clock) or in one process (`lab
simulate`, `lab up --in-process`, a virtual or scaled clock). Both run the same device objects,
and every device, tap and the lab itself answers the same JSON commands: a device's control-port
commands (`{"cmd": "status"}`, the CTC's `{"cmd": "route", ...}`, the trackside's
`{"cmd": "fail_point", ...}`), a tap's (`{"cmd": "cut", "direction": "a>b"}`, `{"cmd": "ber",
"rate": 1e-3}`, `{"cmd": "restore"}`, `{"cmd": "clear"}`), the lab's (`{"cmd": "restart",
"device": NAME}`). Whatever drives a lab -- the procedure runner, the integrated-system property
search, a benchmark -- does so through this protocol, so the same procedure gives the same verdict
on both clocks. Live, the commands go to the control ports (with the lab's token); in process,
straight to the objects.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from ktcs_bench.errors import PeerError
from ktcs_bench.messages import Message


class LabGone(PeerError):
    """Raised by a LabAccess whose lab went away while it was driven: nothing can go on."""


class LabAccess(Protocol):
    """A running lab, live or in one process. Times are the lab's clock, in seconds."""

    @property
    def devices(self) -> dict[str, str]:
        """Device name -> kind (ctc, ixl, atc, trackside, trackcircuit, train)."""
        ...

    @property
    def links(self) -> list[str]:
        """The names of the links (as in the lab file: `st18-atc`, ...)."""
        ...

    def now(self) -> float:
        """The lab's clock (virtual seconds in process; the wall clock's loop time live)."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Let the lab run for `seconds` of its clock."""
        ...

    async def device(self, name: str, obj: Message | Mapping[str, object]) -> dict[str, Any]:
        """A device's control-port command (a message, `ktcs_bench.messages`, or its JSON object)
        and its answer (`{"ok": ..., ...}`)."""
        ...

    async def link(self, name: str, obj: Mapping[str, object]) -> dict[str, Any]:
        """A link's tap command (faults, restore, clear, status) and its answer."""
        ...

    async def lab(self, obj: Mapping[str, object]) -> dict[str, Any]:
        """The lab's own command (status, map, restart, kill) and its answer."""
        ...

    def captures(self) -> dict[str, Path]:
        """Link name -> the capture file the lab keeps of it (pcapng or hex log)."""
        ...
