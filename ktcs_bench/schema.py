"""Declared shapes of the data files: a file's keys and their types are written once as msgspec
Structs (`Shape`), and `convert` turns a parsed YAML document (from `datafiles.load_mapping`, which
keeps its duplicate-key, size, depth and UTF-8 checks) into them.

msgspec's one error -- ``Expected `int`, got `str` - at `$.routes[3].name` `` -- becomes one
ConfigError naming the file, the key path in the project's style (`routes[3].name`) and the
problem in the loaders' words ("must be an integer, not str"), with the line of the file when the
path can be found in it (looked up only when there is an error: loading costs nothing more).
What a shape cannot say -- references between parts, geometry, defaults that hang on other keys --
the loaders check in plain code after the conversion.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, TypeVar

import msgspec

from ktcs_bench.errors import ConfigError, excerpt, kind_of

T = TypeVar("T")


class Shape(msgspec.Struct, forbid_unknown_fields=True):
    """A mapping of a data file: every key declared, any other key refused ("unknown key").
    (Keys with a default come last in a shape: mypy reads a Struct as a dataclass.)"""


_AT = re.compile(r"^(?P<problem>.*?)(?: - at `\$(?P<path>[^`]*)`)?$", re.S)
_EXPECTED = re.compile(r"^Expected `(?P<want>[^`]+)`(?:, got `(?P<got>[^`]+)`)?(?P<rest>.*)$", re.S)
_MISSING = re.compile(r"^Object missing required field `(?P<key>[^`]+)`$")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<key>[^`]+)`$")

_WANT = {
    "int": "an integer",
    "float": "a number",
    "str": "a string",
    "bool": "true or false",
    "array": "a list",
    "object": "a mapping",
    "null": "nothing",
}
_GOT = {"null": "nothing", "array": "list", "object": "dict"}
_BOUNDS = {">=": "at least", "<=": "at most", ">": "greater than", "<": "less than"}
_ABSENT = object()

READER = "reader"
"""The words of `datafiles.YamlReader` (scenario files): "expected a number, got text 'x'",
"must be at least 1, got 0.5", "missing" -- rather than the station loaders' "must be a
number, not str", "must be at least 1", "missing key"."""


def _want(types: str, reader: bool) -> str:
    parts = [t.strip() for t in types.split("|")]
    if "str" in parts:  # text where a number is taken as its digits (`tracks: [1, 2]`)
        return "text" if reader else "a string"
    if "float" in parts:
        return "a number"
    return " or ".join(_WANT.get(p, p) for p in parts if p != "null")


def _bound(rest: str) -> str | None:
    """`>= 1.0` -> "at least 1" (None: not a bound)."""
    for op, words in _BOUNDS.items():
        if rest.startswith(op):
            number = rest[len(op) :].strip()
            try:
                number = f"{float(number):g}"
            except ValueError:
                pass
            return f"{words} {number}"
    return None


def _words(problem: str, style: str = "", value: object = _ABSENT) -> tuple[str, str]:
    """msgspec's problem -> (a key under the error's path or "", the problem in our words;
    `style` READER for the words of `YamlReader`, quoting `value`, the value at fault)."""
    reader = style == READER
    if m := _MISSING.match(problem):
        return m["key"], "missing" if reader else "missing key"
    if m := _UNKNOWN.match(problem):
        return m["key"], "unknown key"
    if m := _EXPECTED.match(problem):
        want = _want(m["want"], reader)
        quoted = "" if value is _ABSENT else f", got {excerpt(value)}"
        if m["got"]:
            if reader and value is not _ABSENT:
                return "", f"expected {want}, got {kind_of(value)} {excerpt(value)}"
            return "", f"must be {want}, not {_GOT.get(m['got'], m['got'])}"
        rest = m["rest"].strip()
        if rest.startswith("of length >= 1"):
            return "", "must not be empty"
        bound = _bound(rest)
        if bound is not None:
            return "", f"must be {bound}{quoted if reader else ''}"
        return "", f"must be {want} {rest}".strip()
    return "", problem


def _value_at(raw: object, steps: list[str | int]) -> object:
    """The parsed value at the key path `steps` (_ABSENT: not there)."""
    for step in steps:
        if isinstance(raw, dict) and step in raw:
            raw = raw[step]
        elif isinstance(raw, list) and isinstance(step, int) and step < len(raw):
            raw = raw[step]
        else:
            return _ABSENT
    return raw


def _steps(path: str) -> list[str | int]:
    """`.routes[3].name` -> ["routes", 3, "name"] (`[...]`, a mapping's key msgspec does not
    name, ends the walk)."""
    out: list[str | int] = []
    for name, index in re.findall(r"\.([^.\[]+)|\[([^\]]*)\]", path):
        if name:
            out.append(name)
        elif index.isdigit():
            out.append(int(index))
        else:
            break
    return out


def _place(steps: list[str | int]) -> str:
    text = ""
    for s in steps:
        text += f"[{s}]" if isinstance(s, int) else (f".{s}" if text else s)
    return text


def line_of(file: str | Path, place: str) -> int | None:
    """The line of `file` (1-based) where the value at the key path `place` starts -- or, when
    its last key is not there (a missing key), where the mapping that lacks it starts. None if
    the file cannot be read again or the path is not in it (a key with a dot in it, a place that
    is no key path)."""
    import yaml

    steps = _steps("." + place if place and not place.startswith("[") else place)
    if _place(steps) != place:
        return None
    loader = yaml.CSafeLoader if yaml.__with_libyaml__ else yaml.SafeLoader  # C: a big file
    try:
        node: Any = yaml.compose(Path(file).read_text(encoding="utf-8"), Loader=loader)
    except (OSError, UnicodeDecodeError, RecursionError, yaml.YAMLError):
        return None
    for i, step in enumerate(steps):
        child = None
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                if isinstance(k, yaml.ScalarNode) and k.value == str(step):
                    child = v
        elif isinstance(node, yaml.SequenceNode) and isinstance(step, int):
            child = node.value[step] if step < len(node.value) else None
        if child is None:
            if i == len(steps) - 1:
                break
            return None
        node = child
    return None if node is None else int(node.start_mark.line) + 1


def located(file: str | Path, place: str, problem: str) -> ConfigError:
    """A ConfigError at the key path `place` of `file`, the problem saying on which line (when
    the path is found in the file as written). Looked up only for an error: loading a good file
    costs nothing more."""
    line = line_of(file, place)
    return ConfigError(file, place, f"{problem} (line {line})" if line else problem)


def error(
    file: str | Path,
    exc: msgspec.ValidationError,
    under: str = "",
    raw: object = _ABSENT,
    style: str = "",
) -> ConfigError:
    """msgspec's ValidationError as the project's ConfigError (`under`: the key path of the part
    converted, "" for the whole file; `raw`: what was converted, to quote the value at fault)."""
    m = _AT.match(str(exc))
    assert m is not None  # the pattern matches any text
    steps = _steps(m["path"] or "")
    key, problem = _words(m["problem"], style, _value_at(raw, steps))
    if key:
        steps.append(key)
    inner = _place(steps)
    place = (f"{under}{inner}" if inner.startswith("[") else f"{under}.{inner}") if under else inner
    return located(file, place, problem)


def convert(raw: object, shape: type[T], file: str | Path, under: str = "", style: str = "") -> T:
    """`raw` (parsed YAML) as `shape`, strictly (no text taken for a number); a mismatch is one
    ConfigError naming `file`, the key path and the line (in the words of `style`: READER for
    the files `YamlReader` reads)."""
    try:
        return msgspec.convert(raw, shape, strict=True)
    except msgspec.ValidationError as exc:
        raise error(file, exc, under, raw, style) from None


def finite(
    value: object,
    file: str | Path,
    place: str = "",
    infinite: frozenset[str] = frozenset(),
    style: str = "",
) -> None:
    """Refuse a number of a converted shape that is NaN or infinite (YAML's .nan, .inf) --
    except under a key in `infinite`, where infinity means "for ever" (NaN never)."""
    if isinstance(value, float):
        key = place.rsplit(".", 1)[-1]
        if math.isnan(value) or (math.isinf(value) and key not in infinite):
            words = (
                "expected a finite number, got"
                if style == READER
                else "must be a finite number, not"
            )
            raise located(file, place, f"{words} {value!r}")
    elif isinstance(value, msgspec.Struct):
        for name in value.__struct_fields__:
            here = f"{place}.{name}" if place else name
            finite(getattr(value, name), file, here, infinite, style)
    elif isinstance(value, (tuple, list)):
        for i, item in enumerate(value):
            finite(item, file, f"{place}[{i}]", infinite, style)
