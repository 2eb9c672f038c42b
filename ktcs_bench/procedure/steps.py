"""The step kinds of a procedure, each read from its YAML mapping (one kind key, its options) and
carried out through the run's context, giving a verdict:

    - ctc: route set 18 S1 S11         a CTC command in the `ctc` console's words; it must be
      refused: conflict                  accepted -- or, with `refused`, refused for that reason
    - ctc: direction 20 1820             (a reason as the interlocking names it: `Reason`, e.g.
                                           `refused: direction`); `direction ST INTERVAL` asks
                                           for the interval's traffic permission
    - local: 18 grant                  the station's local panel: grant | refuse | take, or
                                         control CODE [VALUE]
    - train: T1 place TC1851           a train the procedure moves itself (no process): place AT
    - train: T1 run to 1300 at 30        [length M] [track N] [up|down], run to AT [at KMH],
    - train: T2 place 6420 track 1 down  remove; AT is a chainage in m or a track circuit (its
    - train: 1001 release_eb               middle); the direction it faces (default up) puts its
    - train: 1001 run to 5200              head, its front, that way; the rails move it over the
                                         points as their blades lie. A train device takes its
                                         commands: hold, dispatch [now], run to AT (its ATO
                                         stops there), release_eb
    - fault: link st18-atc cut         a tap's words (cut, restore, ber 1e-3, drop-frame, ...)
    - fault: point 18 31 detection     point detection lost (or jammed); relay TC KIND (a track
    - fault: tc TC1855 failed_occupied   relay), tc TC KIND (the track circuit itself); kill
    - fault: kill ixl20                  DEVICE, restart DEVICE; clear (every fault set so far)
    - wait: 5s
    - wait until: code TC1855 speed > 0
      within: 60s
    - expect: ctc 18 signal 01 is not R   (see `expect` for the words)
      within: 10s                         true at some moment within the time (default 10 s),
    - expect: ixl 18 route 0111 is set    or with `holds: 30s` true throughout that time
      holds: 30s
    - expect: lab invariants hold         the lab safety invariants, looked at every sample
      holds: 60s

Any step may carry `note:`, a sentence for the report. Times are on the lab's clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from ktcs_bench import messages as msg
from ktcs_bench.argtypes import seconds
from ktcs_bench.ctc.log import parse_words
from ktcs_bench.errors import UsageError, excerpt, kind_of
from ktcs_bench.ixl.reasons import Reason
from ktcs_bench.lab.access import LabAccess
from ktcs_bench.messages import Message
from ktcs_bench.procedure.expect import Expectation, Observer, parse_expectation
from ktcs_bench.procedure.names import LabNames, StepError
from ktcs_bench.station.model import Direction
from ktcs_bench.tap.control import parse_command

DEFAULT_WITHIN_S = 10.0
DEFAULT_WAIT_UNTIL_S = 60.0
DEFAULT_RUN_KMH = 30.0
POINT_FAULTS = ("detection", "jammed")
RELAY_FAULTS = ("failed_occupied", "failed_clear")
TC_FAULTS = ("failed_occupied", "failed_clear", "no_code")
TRAIN_DEVICE_VERBS = ("hold", "dispatch [now]", "run to AT", "release_eb")
"""What a train device takes: the operator's orders to its ATO, the driver's EB release."""
LOCAL_ACTIONS = ("grant", "refuse", "take")


MAX_DURATION_S = 24 * 3600.0
"""The longest `wait:`, `within:` or `holds:` (of lab time): longer cannot be meant (a virtual
run spinning through 10000 h); also the most the steps of one procedure may take together."""


def parse_duration(value: object) -> float:
    """`5s`, `500ms`, `2min`, `1.5`, 7 -> seconds (> 0, at most MAX_DURATION_S):
    `argtypes.seconds`, as a StepError."""
    try:
        return seconds(value, maximum=MAX_DURATION_S)
    except ValueError as exc:
        raise StepError(str(exc)) from None


def _note(raw: dict[Any, Any]) -> str:
    """A step's `note:`, a sentence (a bare number is its digits); nothing else."""
    note = raw.get("note")
    if note is None:
        return ""
    if isinstance(note, bool) or not isinstance(note, (str, int, float)):
        raise StepError(f"note: give a sentence as text, not {kind_of(note)} {excerpt(note)}")
    return str(note)


@dataclass
class Outcome:
    verdict: str  # pass | fail | error
    message: str = ""
    seen: str = ""


@dataclass
class Ghost:
    """A train the procedure moves itself, on the track circuits (no process of its own)."""

    train: str
    head: float
    length: float = 40.0
    track: str = "1"
    speed_kmh: float = 0.0
    direction: Direction = "up"  # the way it faces: its head is its front that way

    @property
    def tail(self) -> float:
        return self.head - self.length if self.direction == "up" else self.head + self.length


@dataclass
class FaultBook:
    """Every fault a run set, so that however the run ends it clears them."""

    links: set[str] = field(default_factory=set)
    trackside: set[str] = field(default_factory=set)  # devices with point/relay faults
    track_circuits: set[str] = field(default_factory=set)
    killed: set[str] = field(default_factory=set)

    def __bool__(self) -> bool:
        return bool(self.links or self.trackside or self.track_circuits or self.killed)


class Context(Protocol):
    """What a step runs with (the runner gives it)."""

    access: LabAccess
    names: LabNames
    faults: FaultBook
    ghosts: dict[str, Ghost]

    def elapsed(self) -> float: ...

    async def observe(self) -> Observer: ...

    async def tick(self) -> Observer: ...

    async def action_done(self) -> None: ...

    async def place(self, ghost: Ghost) -> None: ...

    def placed_anew(self, train: str) -> None: ...

    async def clear_faults(self) -> list[str]: ...


def _answer_text(answer: dict[str, Any]) -> str:
    return str(answer.get("result") or answer.get("error") or ("ok" if answer.get("ok") else
                                                                "failed"))  # fmt: skip


def _refusal_words(answer: dict[str, Any]) -> str:
    """What a refusal says, with the interlocking's reason named as `Reason` names it (so that
    `refused: direction` matches reason 7 even where a profile prints only its number)."""
    words = _answer_text(answer).lower()
    reason = answer.get("reason")
    if isinstance(reason, int) and not isinstance(reason, bool):
        try:
            words += f" ({Reason(reason).text})"
        except ValueError:  # a number the bench does not know: its words alone
            pass
    return words


@dataclass
class Step:
    index: int  # 1-based
    kind: str
    text: str
    note: str = ""

    @property
    def title(self) -> str:
        return f"{self.kind}: {self.text}"

    async def run(self, ctx: Context) -> Outcome:
        raise NotImplementedError


# -- actions -------------------------------------------------------------------------------------
@dataclass
class CtcStep(Step):
    command: Message = field(default_factory=msg.Status)
    refused: str | None = None
    ctc: str = "ctc"

    async def run(self, ctx: Context) -> Outcome:
        answer = await ctx.access.device(self.ctc, self.command)
        await ctx.action_done()
        text = _answer_text(answer)
        if self.refused is None:
            if answer.get("ok"):
                return Outcome("pass", text)
            return Outcome("fail", "the CTC command was not accepted", text)
        if not answer.get("ok") and self.refused.lower() in _refusal_words(answer):
            return Outcome("pass", text)
        want = f"refused ({self.refused})"
        return Outcome("fail", f"expected the command {want}", text)


@dataclass
class LocalStep(Step):
    device: str = ""
    command: msg.Local | msg.LocalControl = field(default_factory=lambda: msg.Local(action=""))

    async def run(self, ctx: Context) -> Outcome:
        answer = await ctx.access.device(self.device, self.command)
        await ctx.action_done()
        if answer.get("ok"):
            return Outcome("pass", _answer_text(answer))
        return Outcome("fail", "the local panel's command was not taken", _answer_text(answer))


@dataclass
class TrainStep(Step):
    train: str = ""
    verb: str = ""
    at: float = 0.0
    kmh: float = DEFAULT_RUN_KMH
    length: float | None = None
    track: str | None = None
    direction: Direction | None = None
    device: str | None = None  # a train device: `command` is its command
    command: Message = field(default_factory=msg.Status)

    async def run(self, ctx: Context) -> Outcome:
        if self.device is not None:
            answer = await ctx.access.device(self.device, self.command)
            await ctx.action_done()
            ok = bool(answer.get("ok"))
            return Outcome("pass" if ok else "error", _answer_text(answer))
        ghost = ctx.ghosts.get(self.train)
        if self.verb == "place":
            if ghost is not None:  # put somewhere else: off the rails first, not run there
                tc = ctx.names.device_of("trackcircuit")
                await ctx.access.device(tc, msg.Remove(train=self.train))
            ghost = ctx.ghosts[self.train] = Ghost(
                self.train, self.at, self.length or (ghost.length if ghost else 40.0),
                self.track or (ghost.track if ghost else "1"),
                direction=self.direction or (ghost.direction if ghost else "up"),
            )  # fmt: skip
            await ctx.place(ghost)
            ctx.placed_anew(self.train)
            await ctx.action_done()
            return Outcome("pass", f"head at {ghost.head:g} m")
        if ghost is None:
            return Outcome("error", f"train {self.train} is not on the line: place it first")
        if self.verb == "remove":
            del ctx.ghosts[self.train]
            tc = ctx.names.device_of("trackcircuit")
            await ctx.access.device(tc, msg.Remove(train=self.train))
            await ctx.action_done()
            return Outcome("pass", "removed")
        # run to `at` at `kmh`, one move per sample period of the lab's clock; a point it
        # trails is a fault of its trackside, cleared with the run's faults
        lab = ctx.names.lab
        ctx.faults.trackside.update(d.name for d in lab.devices.values() if d.kind == "trackside")
        await ctx.action_done()
        sense = 1.0 if self.at >= ghost.head else -1.0
        ghost.speed_kmh = self.kmh
        last = ctx.elapsed()
        try:
            while (self.at - ghost.head) * sense > 0:
                await ctx.tick()
                now = ctx.elapsed()
                step = self.kmh / 3.6 * (now - last)
                last = now
                ghost.head = min(ghost.head + step, self.at) if sense > 0 else max(
                    ghost.head - step, self.at)  # fmt: skip
                await ctx.place(ghost)
        finally:
            ghost.speed_kmh = 0.0
        return Outcome("pass", f"head at {ghost.head:g} m")


@dataclass
class FaultStep(Step):
    target: str = ""  # link, point, relay, tc, kill, restart, clear
    name: str = ""  # the link, device or track circuit
    command: dict[str, Any] = field(default_factory=dict)

    async def run(self, ctx: Context) -> Outcome:
        book = ctx.faults
        if self.target == "clear":
            done = await ctx.clear_faults()
            await ctx.action_done()
            return Outcome("pass", "; ".join(done) or "no fault was set")
        # each fault is booked before it is asked for: a run interrupted while the lab carries
        # it out clears it all the same (clearing what was not set does no harm)
        if self.target == "link":
            if self.command.get("cmd") != "status":
                book.links.add(self.name)
            answer = await ctx.access.link(self.name, self.command)
        elif self.target in ("kill", "restart"):
            if self.target == "kill":
                book.killed.add(self.name)
            answer = await ctx.access.lab({"cmd": self.target, "device": self.name})
            if self.target == "restart":
                book.killed.discard(self.name)
        else:
            if self.target in ("point", "relay"):
                book.trackside.add(self.name)
            else:
                book.track_circuits.add(str(self.command.get("tc")))
            answer = await ctx.access.device(self.name, self.command)
        await ctx.action_done()
        if answer.get("ok"):
            return Outcome("pass", _answer_text(answer))
        return Outcome("error", "the fault could not be set", _answer_text(answer))


# -- waits and expectations ----------------------------------------------------------------------
@dataclass
class WaitStep(Step):
    seconds: float = 0.0

    async def run(self, ctx: Context) -> Outcome:
        end = ctx.elapsed() + self.seconds
        while ctx.elapsed() < end:
            await ctx.tick()
        return Outcome("pass")


def seen_text(seen: Any) -> str:
    if isinstance(seen, list) and seen and isinstance(seen[0], dict):
        return "; ".join(f"{e.get('kind')}: {e.get('text')}" for e in seen[:3])
    if isinstance(seen, list) and seen and hasattr(seen[0], "op"):
        return "; ".join(f"{f.direction} {f.op or '?'}{' ' + f.error if f.error else ''}"
                         for f in seen[:3])  # fmt: skip
    if seen is None or seen == []:
        return "nothing" if seen == [] else "no answer"
    if isinstance(seen, float):
        return f"{seen:.2f}".rstrip("0").rstrip(".")
    return str(seen)


@dataclass
class ExpectStep(Step):
    expectation: Expectation | None = None
    within: float = DEFAULT_WITHIN_S
    holds: float | None = None

    async def run(self, ctx: Context) -> Outcome:
        exp = self.expectation
        assert exp is not None
        obs = await ctx.observe()
        start = ctx.elapsed()
        if self.holds is not None:  # true throughout
            while True:
                ok, seen = await exp.check(obs)
                if not ok:
                    at = ctx.elapsed() - start
                    return Outcome("fail", f"did not hold: after {at:.1f} s of {self.holds:g} s",
                                   seen_text(seen))  # fmt: skip
                if ctx.elapsed() - start >= self.holds:
                    return Outcome("pass", f"held {self.holds:g} s", seen_text(seen))
                obs = await ctx.tick()
        while True:  # true at some moment within the limit
            ok, seen = await exp.check(obs)
            if ok:
                return Outcome("pass", f"after {ctx.elapsed() - start:.1f} s", seen_text(seen))
            if ctx.elapsed() - start >= self.within:
                return Outcome("fail", f"not within {self.within:g} s", seen_text(seen))
            obs = await ctx.tick()


# -- reading a step ------------------------------------------------------------------------------
CTC_STEP, TRAIN_STEP = "ctc", "train"  # the step words that name a device kind
KINDS = (CTC_STEP, "local", TRAIN_STEP, "fault", "wait", "wait until", "expect")
OPTIONS = {"ctc": {"refused"}, "expect": {"within", "holds"}, "wait until": {"within"}}


def _place(names: LabNames, word: str) -> float:
    try:
        return float(word)
    except ValueError:
        tc = names.track_circuit(word)
        return (tc.from_m + tc.to_m) / 2


def _train_step(names: LabNames, base: dict[str, Any], text: str) -> TrainStep:
    w = text.split()
    if len(w) < 2:
        raise StepError("train ID ACTION (place AT, run to AT [at KMH], remove; a train "
                        f"device: {', '.join(TRAIN_DEVICE_VERBS)})")  # fmt: skip
    verb, rest = w[1].lower().replace("-", "_"), w[2:]
    if verb == "place" and names.train_device(w[0]) is None:
        names.trains.add(w[0])  # placing a train brings it onto the line
    train = names.train(w[0])
    device = names.train_device(train)
    if device is not None:
        return TrainStep(**base, train=train, verb=verb, device=device,
                         command=_device_order(names, train, device, verb, rest))  # fmt: skip
    if verb == "remove" and not rest:
        return TrainStep(**base, train=train, verb=verb)
    if verb == "place" and rest:
        step = TrainStep(**base, train=train, verb=verb, at=_place(names, rest[0]))
        opts = rest[1:]
        while opts:
            key = opts.pop(0)
            if key in ("up", "down"):
                step.direction = "up" if key == "up" else "down"
            elif key in ("length", "track") and opts:
                value = opts.pop(0)
                if key == "length":
                    step.length = _positive(value, "length")
                else:
                    step.track = value
            else:
                raise StepError(f"train place: unexpected {key!r} (length M, track N, up|down)")
        return step
    if verb == "run" and len(rest) in (2, 4, 5) and rest[0] == "to":
        step = TrainStep(**base, train=train, verb=verb, at=_place(names, rest[1]))
        if len(rest) > 2:
            if rest[2] != "at" or (len(rest) == 5 and rest[4].lower() not in ("kmh", "km/h")):
                raise StepError("train ID run to AT at KMH")
            step.kmh = _positive(rest[3], "speed")
        return step
    raise StepError(f"train {train}: cannot read {' '.join(w[1:])!r} "
                    "(place AT [length M] [track N] [up|down], run to AT [at KMH], remove)")  # fmt: skip


def _device_order(names: LabNames, train: str, device: str, verb: str, rest: list[str]) -> Message:
    """The command a train device takes for `train ID VERB REST...`."""
    if verb == "hold" and not rest:
        return msg.Hold()
    if verb == "release_eb" and not rest:
        return msg.ReleaseEb()
    if verb == "dispatch" and rest in ([], ["now"]):
        return msg.Dispatch(now=bool(rest))
    if verb == "run" and len(rest) == 2 and rest[0] == "to":
        return msg.RunTo(at=_place(names, rest[1]))
    if verb == "run" and rest[:1] == ["to"] and len(rest) > 2:
        raise StepError(f"train {train} runs as device {device}: its ATO sets the speed "
                        "(run to AT, without at KMH)")  # fmt: skip
    raise StepError(f"train {train} runs as device {device}: "
                    f"{', '.join(TRAIN_DEVICE_VERBS)}, not {' '.join([verb, *rest])!r}")  # fmt: skip


def _positive(word: str, what: str) -> float:
    try:
        v = float(word)
    except ValueError:
        raise StepError(f"{what} {word!r} is not a number") from None
    if not v > 0:
        raise StepError(f"{what} must be more than 0, not {word}")
    return v


def _fault_step(names: LabNames, base: dict[str, Any], text: str) -> FaultStep:
    w = text.split()
    if not w:
        raise StepError("fault WHAT: link NAME WORDS, point ST P KIND, relay TC KIND, tc TC KIND, "
                        "kill DEVICE, restart DEVICE, clear")  # fmt: skip
    what = w[0].lower()
    if what == "clear" and len(w) == 1:
        return FaultStep(**base, target="clear")
    if what == "link" and len(w) >= 3:
        lk = names.tapped_link(w[1])
        try:
            cmd = parse_command(" ".join(w[2:]), (lk.a, lk.b))
        except UsageError as exc:
            raise StepError(f"link {lk.name}: {exc}") from None
        if cmd.verb in ("subscribe", "help", "status", "send"):
            raise StepError(f"link {lk.name}: {cmd.verb} is not a fault")
        return FaultStep(**base, target="link", name=lk.name, command=cmd.to_json())
    if what == "point" and len(w) == 4:
        st = names.station(w[1])
        point = names.point(st, w[2])
        if w[3] not in POINT_FAULTS:
            raise StepError(f"point fault {w[3]!r}: one of {', '.join(POINT_FAULTS)}")
        return FaultStep(**base, target="point", name=names.device_of("trackside", st),
                         command=msg.encode(msg.FailPoint(point=point, kind=w[3])))  # fmt: skip
    if what == "relay" and len(w) == 3:
        tc = names.track_circuit(w[1])
        if w[2] not in RELAY_FAULTS:
            raise StepError(f"relay fault {w[2]!r}: one of {', '.join(RELAY_FAULTS)}")
        return FaultStep(**base, target="relay", name=names.device_of("trackside", tc.station),
                         command=msg.encode(msg.FailTrackCircuit(tc=tc.name, kind=w[2])))  # fmt: skip
    if what == "tc" and len(w) == 3:
        tc = names.track_circuit(w[1])
        if w[2] not in TC_FAULTS:
            raise StepError(f"track-circuit fault {w[2]!r}: one of {', '.join(TC_FAULTS)}")
        return FaultStep(**base, target="tc", name=names.device_of("trackcircuit"),
                         command=msg.encode(msg.Fail(tc=tc.name, kind=w[2])))  # fmt: skip
    if what in ("kill", "restart") and len(w) == 2:
        return FaultStep(**base, target=what, name=names.device(w[1]))
    raise StepError(f"cannot read fault {text!r} (link NAME WORDS, point ST P KIND, relay TC "
                    "KIND, tc TC KIND, kill DEVICE, restart DEVICE, clear)")  # fmt: skip


def _local_step(names: LabNames, base: dict[str, Any], text: str) -> LocalStep:
    w = text.split()
    if len(w) < 2:
        raise StepError(f"local STATION {'|'.join(LOCAL_ACTIONS)} (or control CODE [VALUE])")
    st = names.station(w[0])
    ixl = names.device_of("ixl", st)
    if w[1].lower() in LOCAL_ACTIONS and len(w) == 2:
        return LocalStep(**base, device=ixl, command=msg.Local(action=w[1].lower()))
    if w[1].lower() == "control" and len(w) in (3, 4):
        try:
            value = int(w[3], 0) if len(w) == 4 else 1
        except ValueError:
            raise StepError(f"control value {w[3]!r} is not a number") from None
        return LocalStep(**base, device=ixl,
                         command=msg.LocalControl(code=w[2].upper(), value=value))  # fmt: skip
    raise StepError(f"local: cannot read {text!r} ({', '.join(LOCAL_ACTIONS)}, control CODE [V])")


def _askable_interval(names: LabNames, station: int, interval: str) -> None:
    """`interval` borders `station` and has a neighbour to ask (not at the lab's edge)."""
    askable = [iv.name for iv in names.line.view(station).intervals if not iv.boundary]
    if interval not in askable:
        raise StepError(f"ctc: station {station} has no interval {interval!r} to ask the "
                        f"permission of (its: {', '.join(askable) or 'none'})")  # fmt: skip


def parse_step(index: int, raw: object, names: LabNames) -> Step:
    """One step's mapping -> its Step; StepError says what is wrong."""
    if not isinstance(raw, dict):
        raise StepError(f"a step is a mapping such as `expect: ...`, not {excerpt(raw)}")
    kinds = [k for k in raw if k in KINDS]
    if len(kinds) != 1:
        what = f"several ({', '.join(kinds)})" if kinds else "none"
        raise StepError(f"a step has one of {', '.join(KINDS)}: this one has {what}")
    kind = kinds[0]
    allowed = {kind, "note", *OPTIONS.get(kind, set())}
    extra = sorted(str(k) for k in raw if k not in allowed)
    if extra:
        raise StepError(f"{kind}: unknown key {extra[0]!r} (here: {', '.join(sorted(allowed))})")
    value = raw[kind]
    if kind == "wait":
        seconds = parse_duration(value)
        return WaitStep(index, kind, f"{value}", _note(raw), seconds)
    if not isinstance(value, (str, int)) or isinstance(value, bool) or not str(value).strip():
        raise StepError(f"{kind}: give its words as text, not {excerpt(value)}")
    text = str(value).strip()
    base: dict[str, Any] = {"index": index, "kind": kind, "text": text,
                            "note": _note(raw)}  # fmt: skip
    if kind == "ctc":
        try:
            command = parse_words(text.split())
        except UsageError as exc:
            raise StepError(f"ctc: {exc}") from None
        station = getattr(command, "station", None)
        if station is not None:
            names.station(str(station))
        if isinstance(command, msg.AskDirection):
            _askable_interval(names, int(str(command.station)), command.interval)
        refused = raw.get("refused")
        if refused is not None and not isinstance(refused, str):
            raise StepError(f"refused: give the reason's words as text, not {excerpt(refused)}")
        return CtcStep(**base, command=command, refused=refused, ctc=names.device_of("ctc"))
    if kind == "local":
        return _local_step(names, base, text)
    if kind == "train":
        return _train_step(names, base, text)
    if kind == "fault":
        return _fault_step(names, base, text)
    expectation = parse_expectation(text, names)
    if kind == "wait until":
        within = parse_duration(raw.get("within", DEFAULT_WAIT_UNTIL_S))
        return ExpectStep(**base, expectation=expectation, within=within)
    if "within" in raw and "holds" in raw:
        raise StepError("expect: within (true at some moment) or holds (true throughout), not both")
    holds = parse_duration(raw["holds"]) if "holds" in raw else None
    within = parse_duration(raw.get("within", DEFAULT_WITHIN_S))
    return ExpectStep(**base, expectation=expectation, within=within, holds=holds)
