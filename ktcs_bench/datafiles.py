"""Where the shipped data folders are, in a checkout and in an installed wheel.

`protocols/`, `code_charts/` and `emulators/` sit at the repository's top level; the wheel carries
them as `ktcs_bench/_data/<name>` (hatchling force-include). Every loader asks here.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ktcs_bench.errors import ConfigError

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """The shipped data folder `name` ("protocols", "code_charts" or "emulators")."""
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise ConfigError(name, "", "shipped data folder not found (broken installation?)")


def _unique_key_loader(fast: bool = True) -> type:
    """A safe loader whose mappings refuse a key given twice (PyYAML keeps the last silently):
    on libyaml's parser (`yaml.CSafeLoader`, ten times faster) when PyYAML was built with it and
    `fast`, else on the pure-Python one. The key check is the same Python code on both."""
    import yaml

    base = yaml.CSafeLoader if fast and yaml.__with_libyaml__ else yaml.SafeLoader

    class UniqueKeyLoader(base):  # type: ignore[valid-type,misc]
        def construct_mapping(
            self, node: yaml.MappingNode, deep: bool = False
        ) -> dict[object, object]:
            first: dict[object, yaml.Node] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *anchor` merges; what it brings in may be overridden
                key = self.construct_object(key_node, deep=True)
                try:
                    earlier = first.setdefault(key, key_node)
                except TypeError:
                    continue  # an unhashable key: construct_mapping says so below
                if earlier is not key_node:
                    raise yaml.constructor.ConstructorError(
                        None, None,
                        f"duplicate key {key!r} (first on line {earlier.start_mark.line + 1})",
                        key_node.start_mark,
                    )  # fmt: skip
            result: dict[object, object] = super().construct_mapping(node, deep)
            return result

    return UniqueKeyLoader


_LOADERS: dict[bool, type] = {}


def yaml_loader(fast: bool = True) -> type:
    """The one loader class `load_yaml` uses (made once a process)."""
    if fast not in _LOADERS:
        _LOADERS[fast] = _unique_key_loader(fast)
    return _LOADERS[fast]


def yaml_parser_in_c() -> bool:
    """True when `load_yaml` parses with libyaml (C), as it does wherever PyYAML has it."""
    import yaml

    return issubclass(yaml_loader(), yaml.CSafeLoader)


def load_yaml(path: str | Path) -> object:
    """Parse one YAML file: a syntax error, or a mapping key given twice, becomes a ConfigError
    naming the file, the line and column, and the problem.

    libyaml parses; a file it refuses is parsed again by the pure-Python parser, whose words
    (and marks) every error message gives, so an error reads the same with or without libyaml."""
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(p, "", f"cannot read: {exc.strerror or exc}") from None
    try:
        return yaml.load(text, Loader=yaml_loader())  # noqa: S506 -- a safe loader
    except yaml.YAMLError:
        pass
    try:
        return yaml.load(text, Loader=yaml_loader(fast=False))  # noqa: S506 -- a SafeLoader
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        place = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(p, place, f"invalid YAML: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(p, "", f"invalid YAML: {exc}") from None


class YamlReader:
    """Checks the parts of one parsed YAML file; each mistake is one ConfigError naming the file,
    the place (a key path) and what is wrong. Shared by the loaders of scenario and procedure
    files."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, place: str, problem: str) -> ConfigError:
        return ConfigError(self.path, place, problem)

    def mapping(self, obj: object, place: str) -> dict[str, Any]:
        if not isinstance(obj, dict):
            raise self.fail(place, f"expected a mapping, got {type(obj).__name__}")
        return obj

    def seq(self, obj: object, place: str) -> list[Any]:
        if not isinstance(obj, list):
            raise self.fail(place, f"expected a list, got {type(obj).__name__}")
        return obj

    def num(
        self,
        m: dict[str, Any],
        key: str,
        place: str,
        default: float | None = None,
        minimum: float | None = None,
        infinite: bool = False,
    ) -> float:
        """A number at `m[key]`; never NaN, and infinite only where `infinite` says it means
        "for ever" (a zone active until the end)."""
        if key not in m:
            if default is None:
                raise self.fail(f"{place}.{key}", "missing")
            return default
        return self.value(m[key], f"{place}.{key}", minimum, infinite)

    def value(
        self, v: Any, place: str, minimum: float | None = None, infinite: bool = False
    ) -> float:
        """One number of the file (a list item, a field), checked as `num` checks."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(place, f"expected a number, got {v!r}")
        if math.isnan(v) or (math.isinf(v) and not infinite):
            raise self.fail(place, f"expected a finite number, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.fail(place, f"must be at least {minimum}, got {v}")
        return float(v)

    def text(self, m: dict[str, Any], key: str, place: str, default: str | None = None) -> str:
        if key not in m:
            if default is None:
                raise self.fail(f"{place}.{key}", "missing")
            return default
        v = m[key]
        if not isinstance(v, (str, int)) or isinstance(v, bool):
            raise self.fail(f"{place}.{key}", f"expected text, got {v!r}")
        return str(v)

    def flag(self, m: dict[str, Any], key: str, place: str, default: bool) -> bool:
        v = m.get(key, default)
        if not isinstance(v, bool):
            raise self.fail(f"{place}.{key}", f"expected true or false, got {v!r}")
        return v

    def known(self, m: dict[str, Any], keys: set[str], place: str) -> None:
        extra = sorted(set(m) - keys)
        if extra:
            raise self.fail(
                f"{place}.{extra[0]}" if place else str(extra[0]),
                f"unknown key (known: {', '.join(sorted(keys))})",
            )
