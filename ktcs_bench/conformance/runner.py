"""Run the suite against one target: open the line or socket, run each selected case, collect
results. Roles (the device under test) and what the suite plays:

* `atc`, `trackside`: the device's Type I endpoint -- the suite is its IXL;
* `ixl` on a serial endpoint: the suite is its ATC (or IO, `peer="io"`);
* `ixl` with `listen://HOST:PORT`: the suite is the CTC, the IXL connects to it (Type II);
* `ctc` with `tcp://HOST:PORT`: the suite is an IXL client of the CTC (Type II).

With `auto` the device's timers are measured first (a `measure-timings` step, listed and reported
like a case) and the cases judge it by what was measured. A case in which the device sent not one
byte, and that did not pass, stops the run: a dead target costs one case's time limit, and the run
says "no device answered" (`SuiteResult.stopped`; the CLI exits 3).
"""

from __future__ import annotations

import dataclasses
import socket
import ssl
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ktcs_bench import kinds
from ktcs_bench.codec import FrameProfile
from ktcs_bench.conformance import type1_cases, type2_cases
from ktcs_bench.conformance.model import (
    Case,
    CaseContext,
    CaseFailed,
    CaseResult,
    CaseVerdict,
    NotApplicable,
)
from ktcs_bench.conformance.timing import MeasuredTiming, SuiteTiming
from ktcs_bench.conformance.type1_cases import TYPE1_CASES
from ktcs_bench.conformance.type2_cases import TYPE2_CASES
from ktcs_bench.conformance.wire import Evidence, Inconclusive, Type1Wire, Type2Wire
from ktcs_bench.errors import KtcsError, PeerError, UsageError
from ktcs_bench.transport.endpoints import Endpoint, parse_endpoint
from ktcs_bench.transport.serialport import open_transport

ROLES = kinds.CONFORMANCE_KINDS
CASES: dict[str, Case] = {c.name: c for c in (*TYPE1_CASES, *TYPE2_CASES)}
ACCEPT_TIMEOUT = 10.0  # an IXL retries with back-off of at most 5 s
AUTO_LIMIT = 10.0  # --timings auto: the longest the suite waits for any one timer to fire


def _measure_timings(ctx: CaseContext) -> None:
    """The `measure-timings` step of `--timings auto`: passes when every timer was seen."""
    if ctx.type1 is not None:
        type1_cases.measure(ctx, AUTO_LIMIT)
        timers: tuple[str, ...] = ("delta_r", "ack_timeout", "link_test_period", "retry_count")
    else:
        type2_cases.measure(ctx, AUTO_LIMIT)
        timers = ("heartbeat_period", "t2_t_max")
    missing = [k for k in timers if getattr(ctx.measured, k) is None]
    ctx.check(not missing, "every timer measured" + (
        f"; not seen: {', '.join(missing)} (judged by the given timings)" if missing else ""))  # fmt: skip


MEASURE = {
    p: Case(
        "measure-timings",
        p,
        "measure the device's timers first (--timings auto)",
        "§3.4" if p == "type1" else "§4",
        _measure_timings,
    )
    for p in ("type1", "type2")
}


def protocol_of(role: str, target: Endpoint) -> str:
    if role not in ROLES:
        raise UsageError(f"unknown role {role!r} (one of {', '.join(ROLES)})")
    if role == kinds.CTC:
        if target.kind != "tcp":
            raise UsageError("--role ctc needs --target tcp://HOST:PORT (the CTC's Type II server)")
        return "type2"
    if role == kinds.IXL and target.kind in ("listen", "tcp"):
        if target.kind != "listen":
            raise UsageError("the IXL is a Type II client: use --target listen://HOST:PORT")
        return "type2"
    if target.kind not in ("serial",):
        raise UsageError(f"--role {role}: the Type I target is a serial device or pyserial URL")
    return "type1"


def select(protocol: str, role: str, names: Sequence[str] = ()) -> list[Case]:
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise UsageError(f"unknown case(s) {', '.join(unknown)} (see --list)")
    chosen = [c for c in CASES.values() if c.protocol == protocol and role in c.roles]
    if names:
        chosen = [c for c in chosen if c.name in names]
        if not chosen:
            raise UsageError(f"none of {', '.join(names)} applies to --role {role} ({protocol})")
    return chosen


@dataclass
class SuiteResult:
    role: str
    target: str
    protocol: str
    profile: str
    timing: SuiteTiming
    results: list[CaseResult] = field(default_factory=list)
    duration: float = 0.0
    auto: bool = False  # the timings judged by were measured first (--timings auto)
    measured: MeasuredTiming = field(default_factory=MeasuredTiming)
    stopped: str | None = None  # why the run ended before its last case (the device is silent)

    @property
    def failed(self) -> list[CaseResult]:
        return [r for r in self.results if r.verdict in (CaseVerdict.FAIL, CaseVerdict.ERROR)]

    def count(self, verdict: CaseVerdict) -> int:
        return sum(r.verdict is verdict for r in self.results)


class _Type2Opener:
    """Fresh connections to/from the device, one per case."""

    def __init__(self, target: Endpoint, profile: FrameProfile, tls: ssl.SSLContext | None,
                 server_hostname: str | None) -> None:  # fmt: skip
        self.target, self.profile, self.tls = target, profile, tls
        self.server_hostname = server_hostname
        self.server: socket.socket | None = None
        if target.kind == "listen":
            self.server = socket.create_server((target.host, target.port), reuse_port=False)
            self.server.settimeout(ACCEPT_TIMEOUT)

    def __call__(self) -> Type2Wire:
        if self.server is not None:
            try:
                sock, _ = self.server.accept()
            except TimeoutError:
                raise PeerError(
                    f"no IXL connected to {self.target} within {ACCEPT_TIMEOUT:g} s"
                ) from None
            if self.tls is not None:
                sock = self.tls.wrap_socket(sock, server_side=True)
            return Type2Wire(sock, self.profile)
        try:
            sock = socket.create_connection((self.target.host, self.target.port), timeout=5.0)
        except OSError as exc:
            raise PeerError(f"cannot connect to {self.target}: {exc}") from exc
        if self.tls is not None:
            sock = self.tls.wrap_socket(
                sock, server_hostname=self.server_hostname or self.target.host
            )
        return Type2Wire(sock, self.profile)

    def close(self) -> None:
        if self.server is not None:
            self.server.close()


def run_suite(
    role: str,
    target: str,
    profile: FrameProfile,
    timing: SuiteTiming,
    *,
    cases: Sequence[str] = (),
    station: int | None = None,
    codes: int | None = None,
    tls: ssl.SSLContext | None = None,
    server_hostname: str | None = None,
    auto: bool = False,
    on_result: Callable[[SuiteResult, CaseResult], None] | None = None,
    not_applicable: Callable[[Case], str | None] | None = None,
) -> SuiteResult:
    """Run the selected cases (all that apply when none are named) in order; with `auto`,
    measure the device's timers first and judge it by them. `not_applicable` (a device's
    statement, `ics.Ics.not_applicable`) names why a case does not apply: it is reported so,
    never run and never passed."""
    endpoint = parse_endpoint(target)
    protocol = protocol_of(role, endpoint)
    if profile.protocol != protocol:
        raise UsageError(
            f"profile {profile.name} is {profile.protocol}; this target needs {protocol}"
        )
    chosen = select(protocol, role, cases)
    suite = SuiteResult(role, target, protocol, profile.name, timing, auto=auto)
    t0 = time.monotonic()
    wire1: Type1Wire | None = None
    opener: _Type2Opener | None = None
    try:
        if protocol == "type1":
            try:
                transport = open_transport(endpoint.address, f"conformance-{role}", None)
            except KtcsError as exc:
                raise PeerError(str(exc)) from exc
            wire1 = Type1Wire(transport, profile)
            wire1.ack_wait = timing.ack_timeout + timing.tolerance
        else:
            try:
                opener = _Type2Opener(endpoint, profile, tls, server_hostname)
            except OSError as exc:
                raise UsageError(f"cannot listen on {target}: {exc}") from exc
        steps = [MEASURE[protocol], *chosen] if auto else chosen
        for case in steps:
            why = not_applicable(case) if not_applicable is not None else None
            if why is not None:
                result = CaseResult(case, CaseVerdict.NOT_APPLICABLE, f"not applicable: {why}", 0.0,
                                    Evidence())  # fmt: skip
                suite.results.append(result)
                if on_result is not None:
                    on_result(suite, result)
                continue
            result = _run_case(case, role, suite, station, codes, wire1, opener)
            if result.heard == 0 and result.verdict in (CaseVerdict.FAIL, CaseVerdict.ERROR):
                result = _silent_device(suite, result)
            suite.results.append(result)
            if case is MEASURE[protocol]:
                suite.timing = suite.timing.adopt(suite.measured)
                if wire1 is not None:
                    wire1.ack_wait = suite.timing.ack_timeout + suite.timing.tolerance
            if on_result is not None:
                on_result(suite, result)
            if suite.stopped:
                break
    finally:
        if wire1 is not None:
            wire1.close()
        if opener is not None:
            opener.close()
    suite.duration = time.monotonic() - t0
    return suite


def _silent_device(suite: SuiteResult, result: CaseResult) -> CaseResult:
    """The device sent nothing during a case that needed it to: stop the run (exit 3)."""
    ever = any(r.heard for r in suite.results)
    said = "the device stopped answering" if ever else "no device answered"
    suite.stopped = (f"{said}: not one byte from {suite.target} in {result.case.name} "
                     f"({result.duration:.1f} s); the run stops here")  # fmt: skip
    why = ("failed check: " if result.verdict is CaseVerdict.FAIL else "") + result.message
    return dataclasses.replace(result, verdict=CaseVerdict.ERROR, message=f"{said} ({why})")


def _run_case(case: Case, role: str, suite: SuiteResult, station: int | None,
              codes: int | None, wire1: Type1Wire | None,
              opener: _Type2Opener | None) -> CaseResult:  # fmt: skip
    evidence = Evidence()
    heard = 0
    if wire1 is not None:
        wire1.begin(evidence)
        heard = -wire1.heard
    ctx = CaseContext(role, suite.timing, evidence, station, codes, wire1, opener,
                      measured=suite.measured)  # fmt: skip
    t0 = time.monotonic()
    try:
        case.run(ctx)
        verdict, message = CaseVerdict.PASS, ""
    except CaseFailed as exc:
        verdict, message = CaseVerdict.FAIL, str(exc)
    except NotApplicable as exc:
        verdict, message = CaseVerdict.SKIP, str(exc)
    except Inconclusive as exc:
        verdict, message = CaseVerdict.ERROR, f"inconclusive: {exc}"
    except (PeerError, OSError, ssl.SSLError) as exc:
        verdict, message = CaseVerdict.ERROR, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # a bug in a case must not stop the suite
        verdict, message = CaseVerdict.ERROR, f"{type(exc).__name__}: {exc}"
        evidence.note(traceback.format_exc())
    finally:
        for w in ctx.opened:
            w.close()
    heard += wire1.heard if wire1 is not None else sum(w.heard for w in ctx.opened)
    return CaseResult(case, verdict, message, time.monotonic() - t0, evidence, heard)
