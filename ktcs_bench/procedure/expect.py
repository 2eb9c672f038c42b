"""Expectations: what to look at in a running lab (a probe) and what it must show (a predicate),
read from words and checked against the lab's names before anything runs.

    ctc 18 signal 01 is not R          the CTC's indication (what the operator sees)
    ctc 18 route 0111 is set           set | unset
    ctc 18 point 31 is normal locked   as `ctc show` prints it
    ctc 18 mode is center              center | local | requested (CMR up, not yet granted)
    ctc 18 link is up                  up | down;  ctc 18 synced is yes
    ctc 18 tc TC1855 is occupied       occupied | clear;  ctc 18 occupied contains TC1855
    ctc 18 code RSC180111 is 1         any indication code, by name
    ctc 20 interval 1820 is down       the interval's direction (up | down | none | disagree),
    ctc 20 interval 1820 holder is 20    the station holding its permission (or none), the
    ctc 20 interval 1820 asking contains 20   stations asking for it
    ctc 18 view equals ixl             every indication the CTC shows is the IXL's own
    ixl 18 signal 01 is R              the interlocking itself: signal, point, route (idle,
    ixl 18 route 0111 is entered         setting, set, entered, cancelling), mode, link atc|io|ctc,
    ixl 18 link atc is down              tc NAME, occupied
    signal 18 01 is Y,YG,G             short for `ixl 18 signal 01`; `point 18 31` likewise
    lamp 18 01 is R                    the lamp lit at the trackside (dark: none)
    code TC1855 is stop                the wayside ATC's code on a track circuit (a number, or
    code TC1855 speed > 0                stop: the most restrictive); speed km/h, target m
    train T1 tc is TC1855              head, tail (m), speed (km/h), tc (under the head), status
    link st18-atc is down              up when both ends report the link up
    event ixl18 "approach locked"      an event in the device's log since the last action
    no event atc18 "comm"                (`no`: none)
    frame st18-atc atc18>ixl18 op NAK  a frame on the link's capture since the last action
                                         ([DIRECTION] [op NAME] [error KIND]); `no frame ...`
    lab invariants hold                the lab safety invariants (`lab.invariants`, 1-3, 5, 6)
                                         at this sample: none broken since the last sample

Predicates: `is V[,V...]`, `is not V[,V...]`, `> N`, `>= N`, `< N`, `<= N`, `contains X`,
`lacks X`. Words compare without regard to case; numbers as numbers.
"""

from __future__ import annotations

import shlex
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from ktcs_bench import kinds
from ktcs_bench.emulator.device import Event
from ktcs_bench.procedure.names import LabNames, StepError

if TYPE_CHECKING:
    from ktcs_bench.lab.invariants import Violation


@dataclass(frozen=True)
class FrameSeen:
    """A decoded frame of a link's capture: its direction, opcode name, error (None: good)."""

    time: float | None
    direction: str
    op: str | None
    error: str | None
    hex: str


class Observer(Protocol):
    """What a probe reads, as the runner samples it (one status per device per sample)."""

    async def status(self, device: str) -> dict[str, Any] | None: ...

    async def show(self, station: int) -> dict[str, Any] | None: ...

    async def new_events(self, device: str) -> list[Event]: ...

    def new_frames(self, link: str) -> list[FrameSeen]: ...

    def ghost_speed(self, train: str) -> float | None: ...

    async def violations(self) -> list[Violation]:
        """The lab safety invariants found broken at this sample (a `SafetyChecker` fed every
        sample of the run; times since the run began); [] when the run does not check them."""
        ...


Reader = Callable[[Observer], Awaitable[Any]]

OPS = ("is", "is not", ">", ">=", "<", "<=", "contains", "lacks", "occurs", "absent")


def _number(v: object) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(str(v))
    except ValueError:
        return None


@dataclass(frozen=True)
class Predicate:
    op: str
    values: tuple[str, ...] = ()

    def test(self, seen: Any) -> bool:
        if self.op in ("occurs", "absent"):
            return bool(seen) == (self.op == "occurs")
        if seen is None:
            return self.op == "is not"
        if self.op in ("is", "is not"):
            hit = any(_same(seen, v) for v in self.values)
            return hit if self.op == "is" else not hit
        if self.op in ("contains", "lacks"):
            items = {str(x).lower() for x in seen} if isinstance(seen, (list, tuple)) else set()
            hit = self.values[0].lower() in items
            return hit if self.op == "contains" else not hit
        a, b = _number(seen), _number(self.values[0])
        if a is None or b is None:
            return False
        return {">": a > b, ">=": a >= b, "<": a < b, "<=": a <= b}[self.op]

    def words(self) -> str:
        return f"{self.op} {','.join(self.values)}".strip()


def _same(seen: Any, word: str) -> bool:
    a, b = _number(seen), _number(word)
    if a is not None and b is not None:
        return a == b
    return str(seen).strip().lower() == word.strip().lower()


def parse_predicate(words: Sequence[str]) -> Predicate:
    if not words:
        raise StepError("say what it must be: is V, is not V, > N, < N, contains X, lacks X")
    if words[0] == "is" and len(words) > 1 and words[1] == "not":
        op, rest = "is not", words[2:]
    elif words[0] in ("is", "contains", "lacks", ">", ">=", "<", "<="):
        op, rest = words[0], words[1:]
    else:
        raise StepError(f"expected is, is not, >, >=, <, <=, contains or lacks, not {words[0]!r}")
    if not rest:
        raise StepError(f"{op}: give a value")
    if op in ("is", "is not"):
        values = tuple(v.strip() for v in " ".join(rest).split(",") if v.strip())
    else:
        if len(rest) != 1:
            raise StepError(f"{op} takes one value, not {' '.join(rest)!r}")
        values = (rest[0],)
        if op not in ("contains", "lacks") and _number(rest[0]) is None:
            raise StepError(f"{op} takes a number, not {rest[0]!r}")
    return Predicate(op, values)


@dataclass(frozen=True)
class Expectation:
    """One expectation: `read` fetches what is seen, `predicate` judges it."""

    text: str
    read: Reader
    predicate: Predicate
    devices: tuple[str, ...] = ()  # the devices it reads (their events: snapshot at each action)
    links: tuple[str, ...] = ()  # the links whose captures it reads
    other: Reader | None = None  # a second live value it is compared with (`< train T2 tail`)
    offset: float = 0.0  # added to the other value (`- 200`)
    among: tuple[Reader, ...] = ()  # `at most N of A, B is ...`: the values counted
    bound: tuple[str, int] | None = None  # ("most" | "least", N)
    invariants: bool = False  # `lab invariants hold`: the run feeds a SafetyChecker every sample

    async def check(self, obs: Observer) -> tuple[bool, Any]:
        if self.bound is not None:
            seen_all = [await r(obs) for r in self.among]
            hits = sum(self.predicate.test(v) for v in seen_all)
            word, n = self.bound
            ok = hits <= n if word == "most" else hits >= n
            return ok, f"{hits} of {len(seen_all)} ({', '.join(map(str, seen_all))})"
        seen = await self.read(obs)
        if self.other is None:
            return self.predicate.test(seen), seen
        other = _number(await self.other(obs))
        if other is None:
            return False, f"{seen} (the value compared with: nothing)"
        against = other + self.offset
        ok = Predicate(self.predicate.op, (repr(against),)).test(seen)
        return ok, f"{seen} (against {against:g})"


def _route_status(text: object) -> str:
    return str(text).rsplit(".", 1)[-1].lower()


# -- the probes ----------------------------------------------------------------------------------
def _ctc(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if len(w) < 2:
        raise StepError(
            "ctc STATION WHAT: signal S, point P, route R, mode, link, tc T, code C, view"
        )
    ctc = names.device_of("ctc")
    st = names.station(w[0])
    what, rest = w[1].lower(), w[2:]

    async def summary(obs: Observer) -> dict[str, Any] | None:
        status = await obs.status(ctc)
        stations = (status or {}).get("stations") or {}
        s = stations.get(str(st)) or stations.get(st)
        return s if isinstance(s, dict) else None

    def field(key: str, pick: Callable[[dict[str, Any]], Any]) -> Reader:
        async def read(obs: Observer) -> Any:
            s = await summary(obs)
            return None if s is None else pick(s)

        return read

    if what == "signal" and rest:
        sig = names.signal(st, rest[0])
        return field("signals", lambda s: s["signals"].get(sig)), rest[1:], (ctc,)
    if what == "point" and rest:
        pt = names.point(st, rest[0])
        return field("points", lambda s: s["points"].get(pt)), rest[1:], (ctc,)
    if what == "route" and rest:
        rt = names.route(st, rest[0])
        return field("routes", lambda s: "set" if rt in s["routes"] else "unset"), rest[1:], (ctc,)
    if what == "mode":
        return field("mode", lambda s: "requested" if s.get("center_requested") and s["mode"] != "center"
                     else s["mode"]), rest, (ctc,)  # fmt: skip
    if what == "link":
        return field("link", lambda s: s["link"]), rest, (ctc,)
    if what == "synced":
        return field("synced", lambda s: "yes" if s["synced"] else "no"), rest, (ctc,)
    if what == "occupied":
        return field("occupied", lambda s: list(s["occupied"])), rest, (ctc,)
    if what == "routes":
        return field("routes", lambda s: list(s["routes"])), rest, (ctc,)
    if what == "tc" and rest:
        tc = names.track_circuit(rest[0]).name
        return (
            field("tc", lambda s: "occupied" if tc in s["occupied"] else "clear"),
            rest[1:],
            (ctc,),
        )
    if what == "interval" and rest:
        iv, rest = _interval(names, st, rest[0]), rest[1:]
        pick = _INTERVAL_FIELDS["direction"]
        if rest and rest[0].lower() in _INTERVAL_FIELDS:
            pick, rest = _INTERVAL_FIELDS[rest[0].lower()], rest[1:]

        def read_interval(s: dict[str, Any]) -> Any:
            shown = (s.get("intervals") or {}).get(iv)
            return None if not isinstance(shown, dict) else pick(shown)

        return field("intervals", read_interval), rest, (ctc,)
    if what == "code" and rest:
        code = rest[0].upper()

        async def read_code(obs: Observer) -> Any:
            show = await obs.show(st)
            return None if show is None else show.get("state", {}).get(code)

        return read_code, rest[1:], (ctc,)
    if what == "view":
        if rest[:2] != ["equals", "ixl"] or len(rest) != 2:
            raise StepError("ctc STATION view equals ixl")
        ixl = names.device_of("ixl", st)

        async def read_view(obs: Observer) -> Any:
            show, status = await obs.show(st), await obs.status(ixl)
            if show is None or status is None:
                return "unknown (no answer)"
            if not (show.get("summary") or {}).get("known", True):
                return "unknown (the CTC has no full state)"
            ctc_state = list(show.get("state", {}).items())
            ixl_state = status.get("ctc_state", {})
            ixl_values = [ixl_state[k] for k in sorted(ixl_state, key=int)]
            if len(ctc_state) != len(ixl_values):
                return (
                    f"different ({len(ctc_state)} codes at the CTC, {len(ixl_values)} at the IXL)"
                )
            diff = [n for (n, v), x in zip(ctc_state, ixl_values, strict=True) if v != x]
            return "equal" if not diff else f"different ({', '.join(diff[:5])})"

        return read_view, ["is", "equal"], (ctc, ixl)
    raise StepError(f"ctc {st}: unknown {' '.join(w[1:3])!r} (signal, point, route, mode, link, "
                    "synced, occupied, routes, tc, interval, code, view)")  # fmt: skip


_INTERVAL_FIELDS: dict[str, Callable[[dict[str, Any]], Any]] = {
    "direction": lambda i: i.get("direction") or "none",
    "holder": lambda i: "none" if i.get("holder") is None else i["holder"],
    "asking": lambda i: list(i.get("asking") or []),
}
"""What `ctc ST interval IV [direction|holder|asking]` reads of the CTC's interval (SPEC §6.6)."""


def _interval(names: LabNames, station: int, word: str) -> str:
    """`word` as one of the intervals `station` borders; StepError naming them otherwise."""
    mine = [iv.name for iv in names.line.view(station).intervals]
    if word not in mine:
        raise StepError(f"station {station} borders no interval {word!r} (its: {', '.join(mine)})")
    return word


def _ixl(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if len(w) < 2:
        raise StepError("ixl STATION WHAT: signal S, point P, route R, mode, link L, tc T")
    st = names.station(w[0])
    ixl = names.device_of("ixl", st)
    what, rest = w[1].lower(), w[2:]

    def field(pick: Callable[[dict[str, Any]], Any]) -> Reader:
        async def read(obs: Observer) -> Any:
            s = await obs.status(ixl)
            return None if s is None else pick(s)

        return read

    if what == "signal" and rest:
        sig = names.signal(st, rest[0])
        return field(lambda s: s["signals"].get(sig)), rest[1:], (ixl,)
    if what == "point" and rest:
        pt = names.point(st, rest[0])
        return field(lambda s: s["points"].get(pt)), rest[1:], (ixl,)
    if what == "route" and rest:
        rt = names.route(st, rest[0])
        return field(lambda s: _route_status(s["routes"].get(rt))), rest[1:], (ixl,)
    if what == "mode":
        return field(lambda s: s["mode"]), rest, (ixl,)
    if what == "link" and rest and rest[0].lower() in ("atc", "io", "ctc"):
        role = rest[0].lower()
        return field(lambda s: "up" if s["links"].get(role) else "down"), rest[1:], (ixl,)
    if what == "tc" and rest:
        tc = names.track_circuit(rest[0]).name
        return field(lambda s: "occupied" if tc in s["occupied"] else "clear"), rest[1:], (ixl,)
    if what == "occupied":
        return field(lambda s: list(s["occupied"])), rest, (ixl,)
    raise StepError(f"ixl {st}: unknown {' '.join(w[1:3])!r} (signal, point, route, mode, "
                    "link atc|io|ctc, tc, occupied)")  # fmt: skip


def _lamp(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if len(w) < 2:
        raise StepError("lamp STATION SIGNAL")
    st = names.station(w[0])
    sig = names.signal(st, w[1])
    io = names.device_of("trackside", st)
    prefix = f"LPS{st}{sig}"

    async def read(obs: Observer) -> Any:
        s = await obs.status(io)
        if s is None:
            return None
        lit = [
            k[len(prefix) :] for k, v in s.get("state", {}).items() if k.startswith(prefix) and v
        ]
        return ",".join(lit) if lit else "dark"

    return read, w[2:], (io,)


CODE_FIELDS = {"speed": 1, "gradient": 2, "target": 3}


def _code(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if not w:
        raise StepError("code TRACK_CIRCUIT [speed|gradient|target]")
    tc = names.track_circuit(w[0]).name
    atc = names.device_of("atc", names.tcs[tc].station)
    rest = w[1:]
    index = 0
    if rest and rest[0].lower() in CODE_FIELDS:
        index, rest = CODE_FIELDS[rest[0].lower()], rest[1:]

    async def read(obs: Observer) -> Any:
        s = await obs.status(atc)
        code = None if s is None else s.get("codes", {}).get(tc)
        return None if code is None else code[index]

    return read, rest, (atc,)


TRAIN_FIELDS = ("head", "tail", "speed", "tc", "status", "state", "stops", "next_stop",
                "emergency_brakes")  # fmt: skip


def _train(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if len(w) < 2 or w[1].lower() not in TRAIN_FIELDS:
        raise StepError(f"train ID WHAT ({', '.join(TRAIN_FIELDS)})")
    train, what = names.train(w[0]), w[1].lower()
    device = names.train_device(train)
    tc_dev = names.device_of("trackcircuit")
    line_tcs = list(names.tcs.values())

    async def read(obs: Observer) -> Any:
        if device is not None:
            s = await obs.status(device)
            if s is None:
                return None
            head, tail, track = s.get("head"), s.get("tail"), s.get("track") or "1"
            speed, status = s.get("speed_kmh"), s.get("status")
            if what == "state":
                return s.get("state")
            if what == "next_stop":
                return s.get("next_stop")
            if what == "emergency_brakes":  # how often its ATP braked to a stop
                return s.get("emergency_brakes")
            if what == "stops":  # the stations it has stopped at
                return [str(a.get("station")) for a in s.get("arrivals") or []]
        else:
            s = await obs.status(tc_dev)
            pos = None if s is None else s.get("trains", {}).get(train)
            if pos is None:
                return None
            head, tail, track = pos
            speed, status = obs.ghost_speed(train) or 0.0, "placed"
            if what in ("state", "next_stop", "stops", "emergency_brakes"):
                return None  # a train the procedure moves has no service or ATP of its own
        if what == "tc":
            if head is None:
                return None
            x = float(head)
            return next((t.name for t in line_tcs
                         if t.from_m <= x < t.to_m and t.on_track(str(track))), None)  # fmt: skip
        return {"head": head, "tail": tail, "speed": speed, "status": status}[what]

    return read, w[2:], (device or tc_dev,)


def _link(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if not w:
        raise StepError("link NAME")
    lk = names.link(w[0])
    ends = [(lk.a, names.lab.peer_role(lk, lk.a))]
    if lk.type == "type1":  # the peer's own link ("link"), or a neighbouring IXL's to this one
        ends.append((lk.b, names.lab.peer_role(lk, lk.b) if lk.roles else ""))

    async def read(obs: Observer) -> Any:
        for device, role in ends:
            s = await obs.status(device)
            if s is None:
                return "down"
            up = s.get("links", {}).get(role) if role else s.get("link")
            if not up:
                return "down"
        return "up"

    return read, w[1:], tuple(d for d, _ in ends)


def _event(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if len(w) < 2:
        raise StepError('event DEVICE "TEXT" (a part of the event\'s kind and text)')
    device = names.device(w[0])
    text = " ".join(w[1:]).lower()

    async def read(obs: Observer) -> Any:
        return [e for e in await obs.new_events(device)
                if text in f"{e.get('kind', '')}: {e.get('text', '')}".lower()]  # fmt: skip

    return read, [], (device,)


def _frame(names: LabNames, w: list[str]) -> tuple[Reader, list[str], tuple[str, ...]]:
    if not w:
        raise StepError("frame LINK [DIRECTION] [op NAME] [error KIND]")
    lk = names.tapped_link(w[0])
    direction = op = error = None
    rest = w[1:]
    while rest:
        word = rest.pop(0)
        if ">" in word:
            a, _, b = word.replace("->", ">").partition(">")
            if {a, b} != {lk.a, lk.b}:
                raise StepError(f"link {lk.name} goes {lk.a}>{lk.b} or {lk.b}>{lk.a}, not {word}")
            direction = f"{a}>{b}"
        elif word == "op" and rest:
            op = rest.pop(0).upper()
        elif word == "error" and rest:
            error = rest.pop(0).lower()
        else:
            raise StepError(f"frame: unexpected {word!r} (DIRECTION, op NAME, error KIND)")

    async def read(obs: Observer) -> Any:
        return [f for f in obs.new_frames(lk.name)
                if (direction is None or f.direction == direction)
                and (op is None or f.op == op)
                and (error is None or (f.error or "") == error)]  # fmt: skip

    return read, [], ()


PROBES: dict[str, Callable[[LabNames, list[str]], tuple[Reader, list[str], tuple[str, ...]]]] = {
    "ctc": _ctc,
    "ixl": _ixl,
    "lamp": _lamp,
    "code": _code,
    "train": _train,
    "link": _link,
    "event": _event,
    "frame": _frame,
}


COMPARE = (">", ">=", "<", "<=")


def _live_right_side(rest: Sequence[str]) -> bool:
    """`< train T2 tail - 200`: an order compared with another live value, not a number."""
    return len(rest) >= 2 and rest[0] in COMPARE and rest[1].lower() in PROBES


def _right_side(names: LabNames, words: Sequence[str]) -> tuple[Reader, float, tuple[str, ...]]:
    """The other value's reader, the offset added to it (`+ N`, `- N` at the end) and the
    devices it reads."""
    w = list(words)
    offset = 0.0
    if len(w) >= 3 and w[-2] in ("+", "-"):
        n = _number(w[-1])
        if n is None:
            raise StepError(f"{w[-2]} takes a number, not {w[-1]!r}")
        offset = n if w[-2] == "+" else -n
        w = w[:-2]
    head = w[0].lower()
    if head in ("event", "frame"):
        raise StepError("a live value is compared with a value, not with an event or a frame")
    read, left, devices = PROBES[head](names, w[1:])
    if left:
        raise StepError(f"after the value compared with: {' '.join(left)!r} (only + N or - N)")
    return read, offset, devices


def _one_value(names: LabNames, words: list[str]) -> tuple[Reader, tuple[str, ...]]:
    """A value named alone (`ixl 18 signal 12`), its reader and the devices it reads."""
    if not words:
        raise StepError("an empty value in the list")
    head = words[0].lower()
    if head in ("signal", "point") and len(words) >= 3:
        words, head = ["ixl", words[1], head, *words[2:]], "ixl"
    probe = PROBES.get(head)
    if probe is None or head in ("event", "frame"):
        raise StepError(f"{words[0]!r} is no value to count (one of: "
                        f"{', '.join(p for p in PROBES if p not in ('event', 'frame'))})")  # fmt: skip
    read, left, devices = probe(names, words[1:])
    if left:
        raise StepError(f"after {' '.join(words[: len(words) - len(left)])!r}: {' '.join(left)!r}")
    return read, devices


def _counted(text: str, words: list[str], names: LabNames) -> Expectation:
    """`at most N of A, B, ... PREDICATE` (or `at least`): how many of the values satisfy it."""
    if len(words) < 5 or words[3].lower() != "of" or not words[2].isdigit():
        raise StepError("at most N of VALUE, VALUE ... is V (or at least N of ...)")
    body = words[4:]
    at = next((i for i, w in enumerate(body) if w in ("is", ">", ">=", "<", "<=", "contains",
                                                       "lacks")), None)  # fmt: skip
    if not at:
        raise StepError("at most N of VALUE, VALUE ...: say what they are (is V, > N, ...)")
    reads: list[Reader] = []
    devices: list[str] = []
    for part in " ".join(body[:at]).split(","):
        read, devs = _one_value(names, part.split())
        reads.append(read)
        devices += devs
    predicate = parse_predicate(body[at:])
    bound = (words[1].lower(), int(words[2]))
    return Expectation(text, reads[0], predicate, tuple(dict.fromkeys(devices)),
                       among=tuple(reads), bound=bound)  # fmt: skip


INVARIANTS = ("lab", "invariants", "hold")
HOLD = "hold"
"""What `lab invariants hold` reads at a sample where no invariant is broken."""
CHECKED_KINDS = (kinds.TRACKCIRCUIT, kinds.IXL, kinds.TRACKSIDE)
"""The devices a look of the invariants reads (`lab.invariants.snapshot`, without the CTC's
views: invariant 4 asks for a settled line, which a procedure's sample is not)."""


async def _read_invariants(obs: Observer) -> Any:
    """`hold`, or the violations found at this sample (the first three, each with its invariant,
    kind, where and when)."""
    found = await obs.violations()
    if not found:
        return HOLD
    more = f" (and {len(found) - 3} more)" if len(found) > 3 else ""
    return "; ".join(str(v) for v in found[:3]) + more


def _invariants(text: str, words: list[str], names: LabNames) -> Expectation:
    """`lab invariants hold`: the lab safety invariants over every sample of the run."""
    if [w.lower() for w in words] != list(INVARIANTS):
        raise StepError("lab invariants hold (the lab safety invariants, docs/system_safety.md)")
    devices = tuple(d.name for d in names.lab.devices.values() if d.kind in CHECKED_KINDS)
    return Expectation(text, _read_invariants, Predicate("is", (HOLD,)), devices,
                       invariants=True)  # fmt: skip


def parse_expectation(text: str, names: LabNames) -> Expectation:
    """Words -> an Expectation; StepError naming what is wrong."""
    try:
        words = shlex.split(text)
    except ValueError as exc:
        raise StepError(f"cannot read {text!r}: {exc}") from None
    if not words:
        raise StepError("empty expectation")
    if words[0].lower() == "at" and len(words) > 1 and words[1].lower() in ("most", "least"):
        return _counted(text, words, names)
    if words[0].lower() == "lab":
        return _invariants(text, words, names)
    negated = words[0].lower() == "no"
    if negated:
        words = words[1:]
        if not words or words[0].lower() not in ("event", "frame"):
            raise StepError("`no` goes before event or frame")
    head = words[0].lower()
    if head in ("signal", "point") and len(words) >= 3:  # short for the interlocking's own
        words = ["ixl", words[1], head, *words[2:]]
        head = "ixl"
    probe = PROBES.get(head)
    if probe is None:
        raise StepError(f"unknown expectation {words[0]!r} (one of: {', '.join(PROBES)}, "
                        "signal, point, no event, no frame, lab invariants hold)")  # fmt: skip
    read, rest, devices = probe(names, words[1:])
    links: tuple[str, ...] = ()
    if head in ("event", "frame"):
        predicate = Predicate("absent" if negated else "occurs")
        if head == "frame":
            links = (words[1],)
    elif _live_right_side(rest):
        other, offset, more = _right_side(names, rest[1:])
        return Expectation(text, read, Predicate(rest[0], ("0",)), (*devices, *more), links,
                           other, offset)  # fmt: skip
    else:
        predicate = parse_predicate(rest)
        if head == "code" and predicate.op in ("is", "is not"):
            stop = str(names.line.most_restrictive_code.code)
            values = tuple(stop if v.lower() == "stop" else v for v in predicate.values)
            predicate = Predicate(predicate.op, values)
    return Expectation(text, read, predicate, devices, links)
