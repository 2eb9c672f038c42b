"""Running a procedure through a `LabAccess`: the setup, each step with its verdict, the timeline,
and -- however the run ends, Ctrl-C included -- every fault it set cleared.

The run moves on the lab's clock only (`access.now()`, `access.sleep()`): live that is the wall
clock, in one process the virtual one, and the same file gives the same verdicts on both. Every
sample period the runner reads each device's status once (`Snapshot`); expectations judge that
snapshot, and the timeline keeps what changed in it (CTC indications, the interlockings' signals,
the ATC codes, train positions). A procedure that expects `lab invariants hold` has each sample
looked at by the lab's `SafetyChecker` as well (`lab.invariants.snapshot`, from the end of the
setup on), so its checks see the history they need (what a head ran into since the last sample).
"""

from __future__ import annotations

import asyncio
import json
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypedDict, cast

from ktcs_bench import kinds
from ktcs_bench import messages as msg
from ktcs_bench.capture import CaptureRecord, read_capture
from ktcs_bench.capture.hexlog import parse_hex_log
from ktcs_bench.codec.frame import Frame
from ktcs_bench.codec.profile import get_profile
from ktcs_bench.codec.render import payload
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.emulator.device import Event
from ktcs_bench.errors import KtcsError, PeerError
from ktcs_bench.lab.access import LabAccess, LabGone
from ktcs_bench.lab.invariants import SafetyChecker, Violation
from ktcs_bench.lab.invariants import snapshot as lab_snapshot
from ktcs_bench.procedure.expect import FrameSeen, Observer
from ktcs_bench.procedure.model import Procedure
from ktcs_bench.procedure.names import LabNames
from ktcs_bench.procedure.steps import FaultBook, Ghost, Step, seen_text

SAMPLE_S = 0.5  # the lab's seconds between two samples (and two checks of an expectation)
SETUP_S = 60.0  # how long the setup may take to find the lab ready
VERDICTS = ("pass", "fail", "error", "skipped")
ACTIONS = (kinds.CTC, "local", kinds.TRAIN, "fault")
LAB_ERRORS = (KtcsError, OSError, TimeoutError, ConnectionError, ValueError)


class StepJson(TypedDict):
    """A step's result as the JSON report gives it (`StepResult.as_dict`)."""

    step: int
    kind: str
    text: str
    note: str
    verdict: str
    message: str
    seen: str
    start_s: float
    duration_s: float


@dataclass
class StepResult:
    index: int
    kind: str
    text: str
    note: str
    verdict: str = (
        "skipped"  # pass | fail | error | skipped (not run: an earlier step did not pass)
    )
    message: str = ""
    seen: str = ""
    start: float = 0.0  # s since the run began, on the lab's clock
    duration: float = 0.0

    @property
    def title(self) -> str:
        return f"{self.kind}: {self.text}"

    def as_dict(self) -> StepJson:
        return {"step": self.index, "kind": self.kind, "text": self.text, "note": self.note,
                "verdict": self.verdict, "message": self.message, "seen": self.seen,
                "start_s": round(self.start, 3), "duration_s": round(self.duration, 3)}  # fmt: skip


@dataclass(frozen=True)
class Supervised:
    """One sample of a train under ATP: where (head, m), its code's speed, the supervised
    speeds at its front (`limits`: ebi, sbi, warning, permitted, mrsp, km/h) and how many
    emergency brakes it has had."""

    t: float
    head: float
    speed_kmh: float
    code_kmh: float | None
    limits: dict[str, float]
    emergency_brakes: int


@dataclass
class ProcedureResult:
    procedure: Procedure
    mode: str  # "live LAB" | "virtual"
    verdict: str = "error"
    setup_error: str = ""
    steps: list[StepResult] = field(default_factory=list)
    started: float = 0.0  # wall clock (epoch) at the start
    duration: float = 0.0  # s of the lab's clock
    wall_s: float = 0.0
    timeline: list[tuple[float, str, str]] = field(default_factory=list)  # (t, what, value)
    trains: dict[str, list[tuple[float, float, float, float]]] = field(default_factory=dict)
    supervision: dict[str, list[Supervised]] = field(default_factory=dict)
    """A train device's supervision at each sample it ran: its code, curves, emergency brakes."""
    captures: dict[str, list[CaptureRecord]] = field(default_factory=dict)
    link_types: dict[str, str] = field(default_factory=dict)
    cleared: list[str] = field(default_factory=list)
    interrupted: str = ""  # where a SIGINT or SIGTERM stopped it ("in step 3 (wait: 1h)")
    lab_gone: str = ""  # the lab went away during the run (why)
    not_run: str = ""  # why it was not run at all (verdict skipped)
    logs: dict[str, list[Event]] = field(default_factory=dict)
    """The CTC's and the interlockings' event logs over the run (refusals and their reasons,
    ARS, route and signal events), each device's events in its order."""
    broken: list[tuple[float, str, str]] = field(default_factory=list)
    """`always:` expectations broken: (s since the run began, the expectation, what was seen),
    each at the first sample it did not hold."""
    violations: list[Violation] = field(default_factory=list)
    """The lab safety invariants found broken over the run (`lab invariants hold`), each
    (invariant, kind, where) at the first sample it was found, its time since the run began."""

    @property
    def failed_step(self) -> StepResult | None:
        return next((s for s in self.steps if s.verdict in ("fail", "error")), None)

    @property
    def message(self) -> str:
        """What went wrong, in one sentence (empty on a pass)."""
        if self.not_run:
            return f"not run: {self.not_run}"
        if self.interrupted:
            return f"interrupted {self.interrupted}"
        if self.lab_gone:
            return self.lab_gone
        if self.setup_error:
            return f"setup: {self.setup_error}"
        s = self.failed_step
        if self.broken and (s is None or self.broken[0][0] <= s.start + s.duration):
            t, text, seen = self.broken[0]
            return f"always: {text} broken at {t:.1f} s; seen: {seen}"
        if s is None:
            return ""
        seen = f"; seen: {s.seen}" if s.seen else ""
        return f"step {s.index} ({s.title}) {s.verdict}ed: {s.message}{seen}"


def unfinished(procedure: Procedure, mode: str, *, interrupted: str = "",
               not_run: str = "") -> ProcedureResult:  # fmt: skip
    """The result of a procedure a run never carried out: `interrupted` before it began (an
    error), or `not_run` at all (skipped) -- every step skipped."""
    return ProcedureResult(
        procedure, mode, verdict="skipped" if not_run and not interrupted else "error",
        steps=[StepResult(s.index, s.kind, s.text, s.note) for s in procedure.steps],
        started=time.time(), interrupted=interrupted, not_run=not_run,
    )  # fmt: skip


class CaptureCursor:
    """New records of a link's capture file since the cursor was set: a hex log is read from
    where it stood (whole lines only), a pcapng again from the start. The lab is asked for the
    file each time (`captures()` gives it as it stands now)."""

    def __init__(self, access: LabAccess, link: str, path: Path) -> None:
        self.access, self.link = access, link
        self.path = path
        self.offset = 0
        self.count = 0
        self.hex = not str(path).endswith(".pcapng")
        self.start: float | None = None

    def _now(self) -> None:
        self.path = self.access.captures().get(self.link, self.path)

    def set(self) -> None:
        self._now()
        if self.hex:
            self.offset, _ = self._tail(0)
            if self.start is None:
                self.start = self._start()
        else:
            self.count = len(self._all())

    def _start(self) -> float | None:
        try:
            with self.path.open("r", encoding="utf-8", errors="replace") as fh:
                head = fh.read(512)
        except OSError:
            return None
        return parse_hex_log(head).start

    def _tail(self, since: int) -> tuple[int, str]:
        try:
            with self.path.open("rb") as fh:
                fh.seek(since)
                data = fh.read()
        except OSError:
            return since, ""
        cut = data.rfind(b"\n") + 1
        return since + cut, data[:cut].decode("utf-8", errors="replace")

    def _all(self) -> list[CaptureRecord]:
        try:
            return read_capture(self.path).records
        except KtcsError:
            return []

    def new(self) -> list[CaptureRecord]:
        self._now()
        if not self.hex:
            return self._all()[self.count :]
        _, text = self._tail(self.offset)
        base = self.start or 0.0
        return [CaptureRecord(None if r.time is None else base + r.time, r.direction, r.data)
                for r in parse_hex_log(text).records]  # fmt: skip


def decode_frames(records: list[CaptureRecord], profile_name: str) -> list[FrameSeen]:
    profile = get_profile(profile_name)
    out = []
    for rec in records:
        dec = StreamDecoder(profile)
        for frame in [*dec.feed(rec.data), *dec.close()]:
            if isinstance(frame, Frame):
                opcode, _, perr = payload(frame, profile)
                out.append(FrameSeen(rec.time, rec.direction, None if opcode is None else
                                     opcode.name, frame.error or perr, frame.raw.hex()))  # fmt: skip
            else:
                out.append(FrameSeen(rec.time, rec.direction, None, "garbage", frame.raw.hex()))
    return out


def wire(answer: Any) -> dict[str, Any]:
    """An answer as it crosses a control port (JSON): a lab in one process answers with the
    objects themselves (int keys, tuples), a live one with their JSON -- judged alike."""
    out = json.loads(json.dumps(answer))
    return out if isinstance(out, dict) else {}


class Snapshot:
    """One sample of the lab: each device's status read at most once (an `Observer`)."""

    def __init__(self, run: ProcedureRun) -> None:
        self.run = run
        self._status: dict[str, dict[str, Any] | None] = {}
        self._show: dict[int, dict[str, Any] | None] = {}
        self.found: list[Violation] = []  # the lab invariants broken at this sample

    async def status(self, device: str) -> dict[str, Any] | None:
        if device not in self._status:
            try:
                answer = wire(await self.run.access.device(device, msg.Status()))
            except LabGone:
                raise
            except LAB_ERRORS:
                answer = {}
            s = answer.get("status")
            self._status[device] = s if isinstance(s, dict) else None
        return self._status[device]

    async def prefetch(self, devices: list[str]) -> None:
        await asyncio.gather(*(self.status(d) for d in devices if d not in self._status))

    async def show(self, station: int) -> dict[str, Any] | None:
        if station not in self._show:
            try:
                ctc = self.run.names.device_of(kinds.CTC)
                answer = wire(await self.run.access.device(ctc, msg.Show(station=station)))
            except LabGone:
                raise
            except LAB_ERRORS:
                answer = {}
            self._show[station] = answer if answer.get("ok") else None
        return self._show[station]

    async def new_events(self, device: str) -> list[Event]:
        try:
            answer = wire(await self.run.access.device(device, msg.Events(last=2000)))
        except LabGone:
            raise
        except LAB_ERRORS:
            return []
        old = Counter(self.run.event_marks.get(device, Counter()))
        out = []
        for e in answer.get("events", []):
            key = _event_key(e)
            if old[key] > 0:
                old[key] -= 1
            else:
                out.append(e)
        return out

    def new_frames(self, link: str) -> list[FrameSeen]:
        cursor = self.run.action_cursors.get(link)
        if cursor is None:
            return []
        return decode_frames(cursor.new(), self.run.profile_of(link))

    def ghost_speed(self, train: str) -> float | None:
        g = self.run.ghosts.get(train)
        return None if g is None else g.speed_kmh

    async def violations(self) -> list[Violation]:
        return self.found


def _event_key(e: Event) -> tuple[Any, ...]:
    return (e.get("time"), e.get("kind"), e.get("text"))


class ProcedureRun:
    """One procedure on one lab: the `steps.Context` its steps run with."""

    def __init__(self, procedure: Procedure, access: LabAccess, mode: str,
                 sample_s: float = SAMPLE_S, keep_going: bool = False) -> None:  # fmt: skip
        self.procedure = procedure
        self.keep_going = keep_going  # the steps after a failed one still run
        self.watching = False  # the `always:` expectations are checked (after the setup)
        self.access = access
        self.names: LabNames = procedure.names
        self.sample_s = sample_s
        self.faults = FaultBook()
        self.ghosts: dict[str, Ghost] = {}
        self.result = ProcedureResult(procedure, mode)
        self.t0 = access.now()
        self.snapshot = Snapshot(self)
        self.event_marks: dict[str, Counter[tuple[Any, ...]]] = {}
        self.action_cursors: dict[str, CaptureCursor] = {}
        self.run_cursors: dict[str, CaptureCursor] = {}
        self.log_marks: dict[str, Counter[tuple[Any, ...]]] = {}
        self._last: dict[str, str] = {}
        self.event_devices = sorted({d for s in procedure.steps
                                     for d in _expectation_devices(s, "event")})  # fmt: skip
        self.frame_links = sorted({lk for s in procedure.steps for lk in _frame_links(s)})
        lab = procedure.setup.lab
        self.sampled = [d.name for d in lab.devices.values()
                        if d.kind in (kinds.CTC, kinds.IXL, kinds.ATC, kinds.TRACKCIRCUIT, kinds.TRAIN)]  # fmt: skip
        self.checker = SafetyChecker(self.names.line) if procedure.checks_invariants else None

    # -- the context steps run with ------------------------------------------------------------
    def elapsed(self) -> float:
        return self.access.now() - self.t0

    async def observe(self) -> Observer:
        return self.snapshot

    async def tick(self) -> Observer:
        await self.access.sleep(self.sample_s)
        return await self.sample()

    async def sample(self) -> Observer:
        self.snapshot = Snapshot(self)
        await self.snapshot.prefetch(self.sampled)
        await self._record(self.snapshot)
        if self.watching:
            await self._look(self.snapshot)
            await self._always(self.snapshot)
        return self.snapshot

    async def _look(self, snap: Snapshot) -> None:
        """The lab safety invariants at this sample (`lab invariants hold`): a look fed to the
        run's checker, what it finds kept on the sample and, the first time, in the result."""
        if self.checker is None:
            return
        found = self.checker.feed(await lab_snapshot(self.access, views=False))
        snap.found = [replace(v, time=round(v.time - self.t0, 3)) for v in found]
        seen = {(v.invariant, v.kind, v.where) for v in self.result.violations}
        for v in snap.found:
            if (v.invariant, v.kind, v.where) not in seen:
                seen.add((v.invariant, v.kind, v.where))
                self.result.violations.append(v)

    def placed_anew(self, train: str) -> None:
        """A train put somewhere else (not run there): the invariants' checks forget where it
        was, so that the jump is not taken for a run past danger points."""
        last = self.checker.last if self.checker is not None else None
        if self.checker is not None and last is not None and train in last.trains:
            trains = {k: v for k, v in last.trains.items() if k != train}
            self.checker.last = replace(last, trains=trains)

    async def _always(self, snap: Snapshot) -> None:
        """Each `always:` expectation judged on this sample; the first sample one fails on is
        recorded (once: what follows a broken one is in the timeline)."""
        done = {text for _t, text, _s in self.result.broken}
        for exp in self.procedure.always:
            if exp.text in done:
                continue
            ok, seen = await exp.check(snap)
            if not ok:
                self.result.broken.append((round(self.elapsed(), 3), exp.text, seen_text(seen)))

    async def mark(self) -> None:
        """Before each action: expectations of events and frames look at what came after it."""
        for device in self.event_devices:
            try:
                answer = wire(await self.access.device(device, msg.Events(last=2000)))
            except LabGone:
                raise
            except LAB_ERRORS:
                answer = {}
            self.event_marks[device] = Counter(_event_key(e) for e in answer.get("events", []))
        for link in self.frame_links:
            cursor = self.action_cursors.get(link)
            if cursor is not None:
                cursor.set()

    async def action_done(self) -> None:
        """After each action: a fresh sample, so the next expectation sees what it did."""
        await self.sample()

    async def place(self, ghost: Ghost) -> None:
        tc = self.names.device_of(kinds.TRACKCIRCUIT)
        place = msg.Place(train=ghost.train, head=ghost.head, tail=ghost.tail,
                          track=ghost.track, direction=ghost.direction)  # fmt: skip
        answer = await self.access.device(tc, place)
        if not answer.get("ok"):
            raise PeerError(f"the track circuits did not take train {ghost.train}: {answer}")

    async def clear_faults(self) -> list[str]:
        """Clear every fault the run set, and take off the trains it placed; what was done."""
        book, done = self.faults, []
        for link in sorted(book.links):
            await self._quiet(self.access.link(link, {"cmd": "clear"}))
            done.append(f"link {link} cleared")
        for device in sorted(book.trackside):
            await self._quiet(self.access.device(device, msg.ClearFaults()))
            done.append(f"{device} faults cleared")
        tc = self.names.device_of(kinds.TRACKCIRCUIT) if book.track_circuits else ""
        for name in sorted(book.track_circuits):
            await self._quiet(self.access.device(tc, msg.Clear(tc=name)))
            done.append(f"track circuit {name} cleared")
        for device in sorted(book.killed):
            await self._quiet(self.access.lab({"cmd": "restart", "device": device}))
            done.append(f"{device} restarted")
        self.faults = FaultBook()
        return done

    async def _quiet(self, request: Any) -> None:
        try:
            await request
        except LAB_ERRORS:  # a lab that is gone has nothing left to clear
            pass

    def profile_of(self, link: str) -> str:
        lab = self.procedure.setup.lab
        lk = next(x for x in lab.links if x.name == link)
        return lab.type1_profile if lk.type == "type1" else lab.type2_profile

    # -- the timeline ------------------------------------------------------------------------------
    async def _record(self, snap: Snapshot) -> None:
        t = round(self.elapsed(), 3)
        values: dict[str, str] = {}
        ctc = self.names.device_of(kinds.CTC)
        for st, s in ((await snap.status(ctc)) or {}).get("stations", {}).items():
            values[f"ctc {st} link"] = f"{s['link']}{'' if s.get('synced') else ' (not synced)'}"
            values[f"ctc {st} mode"] = s["mode"] + (" (center requested)"
                                                    if s.get("center_requested") else "")  # fmt: skip
            values[f"ctc {st} routes"] = " ".join(s["routes"]) or "-"
            values[f"ctc {st} occupied"] = " ".join(s["occupied"]) or "-"
            for p, v in s["points"].items():
                values[f"ctc {st} point {p}"] = v
            for g, v in s["signals"].items():
                values[f"ctc {st} signal {g}"] = v
        lab = self.procedure.setup.lab
        for d in lab.devices.values():
            s = await snap.status(d.name) if d.name in self.sampled else None
            if s is None:
                continue
            if d.kind == kinds.IXL:
                for g, v in s.get("signals", {}).items():
                    values[f"ixl {d.station} signal {g}"] = str(v)
            elif d.kind == kinds.ATC:
                for tc, code in s.get("codes", {}).items():
                    values[f"code {tc}"] = f"{code[0]} ({code[1]:g} km/h)"
            elif d.kind == kinds.TRACKCIRCUIT:
                for train, (head, tail, _track) in s.get("trains", {}).items():
                    g = self.ghosts.get(train)  # a train device reports itself (below)
                    if g is not None:
                        self._train(train, t, head, tail, g.speed_kmh)
            elif d.kind == kinds.TRAIN and s.get("head") is not None:
                train = str(s.get(kinds.TRAIN, d.name))
                self._train(train, t, s["head"], s["tail"], float(s.get("speed_kmh") or 0.0))
                self._supervised(train, t, s)
        for key, value in values.items():
            if self._last.get(key) != value:
                self._last[key] = value
                self.result.timeline.append((t, key, value))

    def _supervised(self, train: str, t: float, s: dict[str, Any]) -> None:
        limits = s.get("limits_kmh")
        if not isinstance(limits, dict):
            return  # not on the line yet, or a device that does not say
        code = s.get("code")
        series = self.result.supervision.setdefault(train, [])
        if not series or series[-1].t != t:
            series.append(Supervised(
                t, float(s["head"]), float(s.get("speed_kmh") or 0.0),
                float(code[0]) if isinstance(code, list) and code else None,
                {str(k): float(v) for k, v in limits.items()},
                int(s.get("emergency_brakes") or 0),
            ))  # fmt: skip

    def _train(self, train: str, t: float, head: float, tail: float, kmh: float) -> None:
        series = self.result.trains.setdefault(train, [])
        if not series or series[-1][0] != t:
            series.append((t, float(head), float(tail), kmh))

    # -- the run -------------------------------------------------------------------------------------
    def _logged(self) -> list[str]:
        """The devices whose logs the report keeps: the CTC and the interlockings."""
        lab = self.procedure.setup.lab
        return [d.name for d in lab.devices.values() if d.kind in (kinds.CTC, kinds.IXL)
                and d.name in self.access.devices]  # fmt: skip

    async def _log_events(self, device: str) -> list[Event]:
        try:
            answer = wire(await self.access.device(device, msg.Events(last=2000)))
        except LAB_ERRORS:
            return []
        events = answer.get("events", [])
        return (
            [cast(Event, e) for e in events if isinstance(e, dict)]
            if isinstance(events, list)
            else []
        )

    async def _mark_logs(self) -> None:
        for device in self._logged():
            self.log_marks[device] = Counter(_event_key(e) for e in await self._log_events(device))

    async def _collect_logs(self) -> None:
        """Each logged device's events since the run began (those it had before are marked)."""
        for device in self._logged():
            old = Counter(self.log_marks.get(device, Counter()))
            new = []
            for e in await self._log_events(device):
                key = _event_key(e)
                if old[key] > 0:
                    old[key] -= 1
                else:
                    new.append(e)
            if new:
                self.result.logs[device] = new

    async def _setup(self) -> None:
        proc, names = self.procedure, self.names
        ctc = names.device_of(kinds.CTC)
        missing = sorted(proc.devices - set(self.access.devices))
        if missing:
            raise _SetupError(f"the lab has no {', '.join(missing)} (a lab made from "
                              f"{proc.setup.lab.file.name}?)")  # fmt: skip
        await self._mark_logs()
        for link in self.access.links:
            path = self.access.captures().get(link)
            if path is not None:
                self.run_cursors[link] = CaptureCursor(self.access, link, path)
                self.run_cursors[link].set()
                if link in self.frame_links:
                    self.action_cursors[link] = CaptureCursor(self.access, link, path)
        stations = sorted(proc.setup.lab.stations)
        for device in proc.setup.restart:
            answer = await self.access.lab({"cmd": "restart", "device": device})
            if not answer.get("ok"):
                raise _SetupError(f"restart {device}: {answer.get('error') or answer}")

        async def ready() -> str:
            snap = await self.sample()
            s = ((await snap.status(ctc)) or {}).get("stations", {})
            waiting = [st for st in stations
                       if not (s.get(str(st), {}).get("link") == "up"
                               and s.get(str(st), {}).get("synced"))]  # fmt: skip
            return (
                f"station(s) {', '.join(map(str, waiting))} not synced at the CTC"
                if waiting
                else ""
            )

        await self._until(ready, "the lab ready")
        for st in stations:  # as the lab starts them, unless the procedure says otherwise
            await self._mode(st, proc.setup.modes.get(st, proc.setup.lab.ixl_mode))
        if proc.setup.ars or (proc.setup.ars is False and proc.setup.lab.ars is not None):
            for st in stations:
                switch = msg.Ars(station=st, on=bool(proc.setup.ars))
                answer = await self.access.device(ctc, switch)
                if not answer.get("ok"):
                    raise _SetupError(f"ars {'on' if proc.setup.ars else 'off'} at station {st}: "
                                      f"{answer.get('error') or answer}")  # fmt: skip
        ars = proc.setup.ars if proc.setup.ars is not None else proc.setup.lab.ars is not None
        if not ars:  # what an earlier run left set is cancelled (with ARS on, ARS decides)
            await self._cancel_routes(stations)
        for ghost in proc.setup.trains:
            g = self.ghosts[ghost.train] = replace(ghost)
            await self.place(g)
        await self.mark()
        await self.action_done()

    async def _cancel_routes(self, stations: list[int]) -> None:
        names = self.names
        ctc = names.device_of(kinds.CTC)
        s = ((await self.snapshot.status(ctc)) or {}).get("stations", {})
        for st in stations:
            for route_name in s.get(str(st), {}).get("routes", []):
                route = names.line.station(st).route(route_name)
                cancel = msg.Route(action="cancel", station=st, entry=route.entry, exit=route.exit)
                await self.access.device(ctc, cancel)

        async def no_routes() -> str:
            snap = await self.sample()
            s = ((await snap.status(ctc)) or {}).get("stations", {})
            left = [f"{st}:{r}" for st in stations for r in s.get(str(st), {}).get("routes", [])]
            return f"routes still set: {', '.join(left)}" if left else ""

        longest = max((r.approach_release_s for st in stations
                       for r in names.line.station(st).routes), default=0.0)  # fmt: skip
        await self._until(no_routes, "the routes left set cancelled", SETUP_S + longest)

    async def _mode(self, st: int, mode: str) -> None:
        ctc, ixl = self.names.device_of(kinds.CTC), self.names.device_of(kinds.IXL, st)

        async def current() -> dict[str, Any]:
            snap = await self.sample()
            s = ((await snap.status(ctc)) or {}).get("stations", {})
            return dict(s.get(str(st), {}))

        now = await current()
        if now.get("mode") == mode:
            return
        await self.access.device(ctc, msg.Mode(mode=mode, station=st))
        if mode == "center":  # the CMR handshake: the local operator grants it
            await self._until(lambda: self._requested(current), f"station {st} asking for center")
            await self.access.device(ixl, msg.Local(action="grant"))

        async def reached() -> str:
            m = (await current()).get("mode")
            return "" if m == mode else f"station {st} in {m} mode"

        await self._until(reached, f"station {st} in {mode} mode")

    async def _requested(self, current: Any) -> str:
        s = await current()
        return "" if s.get("center_requested") or s.get("mode") == "center" else "no CMR"

    async def _until(self, check: Any, what: str, limit: float = SETUP_S) -> None:
        start = self.elapsed()
        while True:
            why = await check()
            if not why:
                return
            if self.elapsed() - start > limit:
                raise _SetupError(f"{what}: not within {limit:g} s ({why})")
            await self.access.sleep(self.sample_s)

    async def run(self) -> ProcedureResult:
        """The setup and the steps, then -- however they end, a cancellation (the user's
        SIGINT or SIGTERM) included -- the faults cleared and the trains taken off."""
        result = self.result
        result.started = time.time()
        wall0 = time.monotonic()
        result.steps = [StepResult(s.index, s.kind, s.text, s.note) for s in self.procedure.steps]
        result.link_types = {lk.name: lk.type for lk in self.procedure.setup.lab.links}
        try:
            try:
                await self._setup()
            except _SetupError as exc:
                result.setup_error = str(exc)
            except LabGone:
                raise
            except LAB_ERRORS as exc:
                result.setup_error = f"the lab did not answer: {exc}"
            if not result.setup_error:
                self.watching = True
                await self._look(self.snapshot)  # the state the setup left
                await self._always(self.snapshot)
                for step, sr in zip(self.procedure.steps, result.steps, strict=True):
                    await self._step(step, sr)
                    if sr.verdict == "error" or (sr.verdict == "fail" and not self.keep_going):
                        break  # a step in error leaves nothing certain to go on from
                self.watching = False
        except LabGone as exc:
            result.lab_gone = str(exc)
        except asyncio.CancelledError:  # interrupted: the faults are cleared all the same, below
            s = next((s for s in result.steps if s.message == "interrupted"), None)
            self._interrupted(f"in step {s.index} ({s.title})" if s else "during its setup")
        finally:
            try:
                if not result.lab_gone:
                    try:
                        await self._collect_logs()
                    except LabGone:
                        pass  # the logs are evidence, not worth a wind-up missed
                    except asyncio.CancelledError:
                        self._interrupted("while reading the devices' logs")
                try:
                    await self._wind_up()
                except asyncio.CancelledError:  # interrupted as it wound up: it winds up again
                    self._interrupted("while clearing its faults")
                    await self._wind_up()
            finally:
                result.captures = {k: c.new() for k, c in self.run_cursors.items()}
                result.duration = self.elapsed()
                result.wall_s = time.monotonic() - wall0
                verdicts = {s.verdict for s in result.steps}
                if (result.setup_error or "error" in verdicts or result.interrupted
                        or result.lab_gone):  # fmt: skip
                    result.verdict = "error"
                elif "fail" in verdicts or result.broken:
                    result.verdict = "fail"
                else:
                    result.verdict = "pass"
        return result

    def _interrupted(self, where: str) -> None:
        """A cancellation caught: noted, and taken back, so that the run can wind up."""
        self.result.interrupted = self.result.interrupted or where
        task = asyncio.current_task()
        if task is not None:
            task.uncancel()

    async def _wind_up(self) -> None:
        """Every fault the run set cleared, every train it placed taken off (again, if an
        interrupt cut the first attempt short: clearing twice does no harm)."""
        result = self.result
        result.cleared = await self.clear_faults()
        for train in list(self.ghosts):
            tc = self.names.device_of(kinds.TRACKCIRCUIT)
            await self._quiet(self.access.device(tc, msg.Remove(train=train)))
            result.cleared.append(f"train {train} taken off")
        self.ghosts.clear()

    async def _step(self, step: Step, sr: StepResult) -> None:
        sr.start = self.elapsed()
        try:
            if step.kind in ACTIONS:
                await self.mark()
            outcome = await step.run(self)
            sr.verdict, sr.message, sr.seen = outcome.verdict, outcome.message, outcome.seen
        except LabGone as exc:
            sr.verdict, sr.message = "error", str(exc)
            raise
        except LAB_ERRORS as exc:
            sr.verdict, sr.message = "error", f"the lab did not answer: {exc}"
        except asyncio.CancelledError:
            sr.verdict, sr.message = "error", "interrupted"
            sr.duration = self.elapsed() - sr.start
            raise
        sr.duration = self.elapsed() - sr.start


class _SetupError(Exception):
    pass


def _expectation_devices(step: Step, head: str) -> tuple[str, ...]:
    exp = getattr(step, "expectation", None)
    if exp is None or not exp.text.split() or head not in exp.text.split()[:2]:
        return ()
    return tuple(exp.devices)


def _frame_links(step: Step) -> tuple[str, ...]:
    exp = getattr(step, "expectation", None)
    return () if exp is None else tuple(exp.links)


async def run_procedure(procedure: Procedure, access: LabAccess, mode: str,
                        sample_s: float = SAMPLE_S, keep_going: bool = False) -> ProcedureResult:  # fmt: skip
    """The procedure's run; `keep_going`: the steps after a failed expectation still run (and
    are reported after it), so the moments after an unsafe state are recorded too."""
    return await ProcedureRun(procedure, access, mode, sample_s, keep_going).run()
