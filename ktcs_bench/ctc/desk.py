"""The operator's desk: one operator command carried out on the CTC's Type II server, and logged.

`Desk.operate(command)` is the one way a command goes out, whoever gives it (`ktcs-bench ctc`
through the CTC's control port, or a click on the web console): the model turns it into an
`Action` (or refuses it), the server sends the CONTROL and waits for its CONTROL_RESULT, and the
command log records the command in the operator's words with what came of it. `outstanding`
counts, per station, the controls sent and awaiting their CONTROL_RESULT (the console bounds it).

The desk reads no clock of its own: `clock` is the lab's, given by whoever builds the desk (the
CTC device passes its own, wall time live and the loop's virtual time in a lab in one process), so
the log's times and durations are the lab's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.ctc.log import CommandLog
from ktcs_bench.ctc.model import Action, CtcModel
from ktcs_bench.errors import PeerError, UsageError
from ktcs_bench.messages import OperatorCommand
from ktcs_bench.transport.ctc_server import CtcServer

log = logging.getLogger("ktcs_bench.ctc")

CONTROL_TIMEOUT_S = 10.0  # CONTROL -> CONTROL_RESULT


@dataclass(frozen=True)
class Outcome:
    """What came of one operator command."""

    action: Action | None  # None: refused by the CTC, nothing was sent
    accepted: bool = False  # the IXL accepted it
    why: str | None = None  # unless accepted: the rejection reason, the refusal, or why no answer
    reason: int | None = None  # the CONTROL_RESULT reason number, when the IXL answered

    @property
    def answered(self) -> bool:
        return self.reason is not None

    @property
    def result(self) -> str:
        """ "accepted", "rejected: <reason as protocols/type2.yaml names it>", or `why`."""
        if self.accepted:
            return "accepted"
        return f"rejected: {self.why}" if self.answered else str(self.why)


class Desk:
    """Carries out operator commands for one CTC (`model` reads the tables `server` feeds);
    `clock` gives the lab's time, in seconds, for the command log."""

    def __init__(
        self,
        model: CtcModel,
        server: CtcServer,
        *,
        clock: Callable[[], float],
        timeout: float = CONTROL_TIMEOUT_S,
    ) -> None:
        self.model = model
        self.server = server
        self.clock = clock
        self.timeout = timeout
        self.log = CommandLog()
        self.outstanding: dict[int, int] = {}  # station -> controls awaiting their result

    async def operate(
        self,
        command: OperatorCommand | Mapping[str, Any],
        source: str = kinds.CTC,
        on_sent: Callable[[Action], None] | None = None,
    ) -> Outcome:
        """Carry out one command (a message, or its JSON object: `CtcModel.action`); `on_sent` is
        told as its CONTROL goes out."""
        entry = self.log.record(self.clock(), command, source)
        try:
            action = self.model.action(command)
        except UsageError as exc:
            entry["result"] = f"refused by the CTC: {exc}"
            log.warning("command %s refused: %s", entry["command"], exc)
            return Outcome(None, why=str(exc))
        entry["code"] = action.name
        if on_sent is not None:
            on_sent(action)
        t0 = self.clock()
        st = action.station
        self.outstanding[st] = self.outstanding.get(st, 0) + 1
        try:
            answer = await self.server.control(st, action.code, action.value, self.timeout)
        except TimeoutError:
            why = f"no CONTROL_RESULT from station {action.station} within {self.timeout:g} s"
        except (UsageError, PeerError) as exc:  # not connected, or the link went while waiting
            why = str(exc)
        else:
            why = answer.reason_name or f"reason {answer.reason}"
            outcome = Outcome(action, answer.accepted, None if answer.accepted else why,
                              answer.reason)  # fmt: skip
            entry["result"], entry["seconds"] = outcome.result, round(self.clock() - t0, 4)
            log.info("station %d %s=%d -> %s", action.station, action.name, action.value,
                     outcome.result)  # fmt: skip
            return outcome
        finally:
            self.outstanding[st] -= 1
        entry["result"] = f"no result: {why}"
        return Outcome(action, why=why)
