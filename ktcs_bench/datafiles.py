"""Where the shipped data folders are, in a checkout and in an installed wheel.

`protocols/`, `code_charts/` and `emulators/` sit at the repository's top level; the wheel carries
them as `ktcs_bench/_data/<name>` (hatchling force-include). Every loader asks here.
"""

from __future__ import annotations

from pathlib import Path

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
