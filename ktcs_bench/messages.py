"""The control plane's messages: every `{"cmd": ...}` a device's JSON-lines control port takes, as
a typed class, decoded once where the JSON comes in.

Each command is a msgspec Struct tagged by its "cmd" (`Route` is `{"cmd": "route", ...}`);
the commands a device kind takes are one tagged union (`CTC`, `IXL`, `TRACKSIDE`,
`TRACK_CIRCUITS`, `TRAIN`, each with `DEVICE`'s status, events and stop), and `decode(obj,
union)` turns a JSON object into its message or one clear error -- an unknown cmd, a key missing or
misspelt, a value of the wrong type -- which the port answers as `{"ok": false, "error": ...}`.
The handlers then dispatch on the message's class (`match`), never on strings; `encode` gives a
message's JSON object back (a message round-trips: `decode(encode(m), union) == m`).

The CTC's operator commands (`OperatorCommand`: route, point, signal, mode, direction, control) are one
message whoever gives them: the `ctc` console's words (`ctc.log.parse_words`), automatic route
setting, procedures, the web console's clicks (read into it by the desk:
`ctc.model.operator_command`) -- and the command log says them in the operator's words from the
same message.

The answers are typed too (`Answer`: `Refused` is the one error shape, `StatusAnswer`,
`ShowAnswer`, `ControlAnswer`, ...): a handler returns one, the port sends its JSON object
(`answer`). What they carry -- a device's status, a station's summary, the logs -- is each
device's own JSON.

Sans-I/O: it imports msgspec and nothing of the bench.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any, Literal, TypedDict, get_args

import msgspec


class Message(msgspec.Struct, tag_field="cmd", forbid_unknown_fields=True, kw_only=True,
              omit_defaults=True):  # fmt: skip
    """A control-port command: its class is its "cmd"."""

    @classmethod
    def cmd(cls) -> str:
        """Its "cmd" (the Struct's tag)."""
        tag = cls.__struct_config__.tag
        assert isinstance(tag, str)
        return tag


JsonObject = dict[str, object]
"""A JSON object whose keys and values are whatever its sender put there (a rails peer's hello, as
it said it): read it by checking each value's type."""


class ReadyInfo(TypedDict, total=False):
    """Where a started device can be reached: its control port, its Type II or rails port
    (`listen`), its web console, its ptys (peer -> path)."""

    control: str
    listen: str
    console: str
    ptys: dict[str, str]


class ReadyLine(ReadyInfo, total=False):
    """A device process's ready line (its first line on stdout): its name and kind, and its
    `ReadyInfo`."""

    ready: str
    kind: str


# -- every device -------------------------------------------------------------------------------


class Status(Message, tag="status"):
    """The device's status: `{"ok": true, "status": {...}}`."""


class Events(Message, tag="events"):
    """Its last `last` events (kind, text, time)."""

    last: int = 50


class Stop(Message, tag="stop"):
    """Stop the device (its process ends)."""


# -- the CTC --------------------------------------------------------------------------------------

StationRef = int | str | None
"""A station by number (18 or "18"); None: the CTC's only station."""


class Route(Message, tag="route"):
    """Set a route from `entry` to `exit` (signal names, "S1" or "01"), or cancel the route set
    from `entry` (`exit` names it, or is left out)."""

    entry: str
    action: Literal["set", "cancel"] = "set"
    station: StationRef = None
    exit: str | None = None


class Point(Message, tag="point"):
    """Move a point: `position` is "normal" or "reverse" (the model says so when it is not)."""

    point: str
    position: str
    station: StationRef = None


class Signal(Message, tag="signal"):
    """Put a signal to stop, or release it ("stop" | "release")."""

    signal: str
    action: str = "stop"
    station: StationRef = None


class Mode(Message, tag="mode"):
    """Center or local control of a station ("center" | "local")."""

    mode: str
    station: StationRef = None


class AskDirection(Message, tag="direction"):
    """Ask the neighbour for `interval`'s traffic permission (SPEC §6.6), ahead of a departure
    route into it from `station`: its IXL answers accepted (asked) or refused."""

    interval: str
    station: StationRef = None


class Control(Message, tag="control"):
    """A control code of the station's CTC->IXL chart by name, and its value."""

    code: str
    station: StationRef = None
    value: int = 1


OperatorCommand = Route | Point | Signal | Mode | AskDirection | Control
"""What the operator's desk carries out (`ctc.desk.Desk.operate`)."""


class Show(Message, tag="show"):
    """One station's picture: `{"summary": ..., "state": ...}`."""

    station: StationRef = None


class Log(Message, tag="log"):
    """The command log's last `last` entries."""

    last: int = 50


class Ars(Message, tag="ars"):
    """Automatic route setting: its state and last `last` log entries; `on` switches it first (at
    `station`, else everywhere)."""

    station: StationRef = None
    on: bool | None = None
    last: int = 20


class TimedRoute(Message, tag="timed_route"):
    """Set a route and time CONTROL -> CONTROL_RESULT -> the entry signal's proceed (benchmarks)."""

    entry: str
    exit: str
    station: StationRef = None
    timeout: float = 30.0


class AddTrain(Message, tag="add_train"):
    """A train process the web console may draw: its name and control port (HOST:PORT)."""

    train: str
    control: str


# -- the interlocking -----------------------------------------------------------------------------


class LocalControl(Message, tag="control"):
    """The local panel: a control code by name (or by number in the CTC->IXL chart)."""

    code: str | int
    value: int = 1


class Local(Message, tag="local"):
    """The local operator in the CMR handshake: "grant" | "refuse" | "take"."""

    action: str


# -- trackside I/O --------------------------------------------------------------------------------


class FailPoint(Message, tag="fail_point"):
    point: str
    kind: str


class FailLamp(Message, tag="fail_lamp"):
    signal: str
    aspect: str


class FailTrackCircuit(Message, tag="fail_track_circuit"):
    tc: str
    kind: str


class ClearFaults(Message, tag="clear_faults"):
    """Every trackside fault cleared."""


# -- the track circuits (the rails) ---------------------------------------------------------------


class Fail(Message, tag="fail"):
    """A track circuit failed: `kind` as `atc.track_circuits` names them (failed_occupied, ...)."""

    tc: str
    kind: str


class Clear(Message, tag="clear"):
    """One track circuit's fault cleared (`tc`), or every one."""

    tc: str | None = None


class Place(Message, tag="place"):
    """A train with no process of its own on the rails: head and tail in m on the line; the track
    it is put on; the way it faces (its head is its front that way). Placed again: it moves."""

    train: str
    head: float
    tail: float
    track: str = "1"
    direction: Literal["up", "down"] = "up"


class Remove(Message, tag="remove"):
    train: str


# -- a train --------------------------------------------------------------------------------------


class ReleaseEb(Message, tag="release_eb"):
    """The driver releases the emergency brake."""


class Hold(Message, tag="hold"):
    """Hold the train at its next stop."""


class Dispatch(Message, tag="dispatch"):
    """Let a held train go (`now`: at once, not at its timetable's time)."""

    now: bool = False


class RunTo(Message, tag="run_to"):
    """Run on to `at` (m on the line) and stop there."""

    at: float


class SpeedDistance(Message, tag="speed_distance"):
    """The speed-distance data of the run so far (the web console's panel)."""


TrainOrder = Hold | Dispatch | RunTo

# -- what each kind of device takes ---------------------------------------------------------------

DEVICE = Status | Events | Stop
CTC = (Status | Events | Stop | Show | Log | Route | Point | Signal | Mode | AskDirection
       | Control | Ars | TimedRoute | AddTrain)  # fmt: skip
IXL = Status | Events | Stop | LocalControl | Local
TRACKSIDE = Status | Events | Stop | FailPoint | FailLamp | FailTrackCircuit | ClearFaults
TRACK_CIRCUITS = Status | Events | Stop | Fail | Clear | Place | Remove
TRAIN = Status | Events | Stop | ReleaseEb | Hold | Dispatch | RunTo | SpeedDistance
ATC = DEVICE


class BadMessage(ValueError):
    """A JSON object that is not a message the port takes; its text is the port's error answer."""


def members(union: object) -> tuple[type[Message], ...]:
    return tuple(get_args(union)) or (union,)  # type: ignore[return-value]


def decode(obj: Mapping[str, object], union: object) -> Message:
    """The message `obj` (a JSON object, the token already taken off) is, of those in `union`;
    BadMessage with one clear sentence when it is none of them."""
    try:
        message: Message = msgspec.convert(obj, union)
    except msgspec.ValidationError as exc:
        raise BadMessage(_clear(obj, union, str(exc))) from None
    return message


def encode(message: Message) -> dict[str, object]:
    """The message's JSON object (its defaults left out), as a client sends it."""
    out = msgspec.to_builtins(message)
    assert isinstance(out, dict)
    return out


def _words(annotation: object) -> str:
    """A field's type as an error says what the value must be."""
    text = str(annotation)
    if "Literal" in text:
        return " or ".join(repr(a) for a in get_args(annotation)) or text
    kinds = [k for k in ("bool", "int", "float", "str") if re.search(rf"\b{k}\b", text)]
    said = {"bool": "true or false", "int": "an integer", "float": "a number", "str": "text"}
    return " or ".join(said[k] for k in kinds) or text


def _clear(obj: Mapping[str, object], union: object, error: str) -> str:
    """msgspec's validation error as one sentence in the port's words."""
    kinds = {m.cmd(): m for m in members(union)}
    cmd = obj.get("cmd")
    if "cmd" not in obj:
        return f'a command needs "cmd" (one of {", ".join(sorted(kinds))})'
    if not isinstance(cmd, str) or cmd not in kinds:
        return f"unknown command {cmd!r} (this port takes {', '.join(sorted(kinds))})"
    cls = kinds[cmd]
    fields = msgspec.structs.fields(cls)
    keys = ", ".join(f.encode_name for f in fields) or "none"
    if m := re.match(r"Object contains unknown field `(.+)`", error):
        return f"{cmd}: unknown key {m.group(1)!r} (its keys: {keys})"
    if m := re.match(r"Object missing required field `(.+)`", error):
        return f"{cmd} command without {m.group(1)!r} (its keys: {keys})"
    if m := re.search(r" - at `\$\.([A-Za-z_]\w*)`$", error):
        key = m.group(1)
        field = next((f for f in fields if f.encode_name == key), None)
        if field is not None:
            return f"{cmd}: {key} must be {_words(field.type)}, not {obj.get(key)!r}"
    return f"{cmd}: {error}"


# -- answers --------------------------------------------------------------------------------------
# What a port answers, `{"ok": ..., ...}`: its JSON object is `answer(...)`. The payloads (a
# device's status, a station's summary, the logs) are each device's own JSON.


class Answer(msgspec.Struct, kw_only=True):
    """`{"ok": true}`: done."""

    ok: bool = True


class Refused(Answer, kw_only=True):
    """`{"ok": false, "error": ...}`: not done, and why (the one shape of every port's error)."""

    ok: bool = False
    error: str


class StatusAnswer(Answer, kw_only=True):
    status: object


class EventsAnswer(Answer, kw_only=True):
    events: Sequence[object]


class ShowAnswer(Answer, kw_only=True):
    summary: object
    state: object


class LogAnswer(Answer, kw_only=True):
    log: Sequence[object]


class ArsAnswer(Answer, kw_only=True):
    ars: object
    log: Sequence[object]


class ControlAnswer(Answer, kw_only=True):
    """The CTC's control sent and its CONTROL_RESULT: accepted (ok) or the reason."""

    code: str
    result: str
    reason: int | None


class TimedAnswer(ControlAnswer, kw_only=True):
    """`ControlAnswer` and the times (s) to the result and to the entry signal's proceed."""

    result_s: float
    proceed_s: float


class ReasonAnswer(Answer, kw_only=True):
    """The local panel's control: accepted (ok) or the reason's number."""

    reason: int


class ModeAnswer(Answer, kw_only=True):
    mode: str


class ResultAnswer(Answer, kw_only=True):
    """A train's order carried out, in the ATO's words."""

    result: str


class DataAnswer(Answer, kw_only=True):
    data: object


def answer(reply: Answer) -> dict[str, Any]:
    """An answer's JSON object, as the port sends it."""
    out = msgspec.to_builtins(reply)
    assert isinstance(out, dict)
    return out
