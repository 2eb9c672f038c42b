"""Where the shipped data folders are, in a checkout and in an installed wheel.

`protocols/`, `code_charts/` and `emulators/` sit at the repository's top level; the wheel carries
them as `ktcs_bench/_data/<name>` (hatchling force-include). Every loader asks here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ktcs_bench.errors import ConfigError, excerpt, kind_of

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """The shipped data folder `name` ("protocols", "code_charts" or "emulators")."""
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise ConfigError(name, "", "shipped data folder not found (broken installation?)")


MAX_YAML_BYTES = 16 * 1024 * 1024
"""The largest data file read (the shipped ones are under 100 kB; a generated line a few MB)."""
MAX_ALIAS_NODES = 10_000
"""How many values aliases (`*name`, `<<: *name`) may repeat in one file, all uses together --
a use repeats the whole of what its anchor holds, aliases within it included (nested anchors
nine deep, nine uses each, are a 'billion laughs' bomb: 2.5 GB once written out)."""
MAX_DEPTH = 100
"""How deep collections may nest (the shipped files nest under ten)."""


class _Refused(Exception):
    """The loader refuses a document it can parse (too deep, aliases repeating too much): a
    problem at a line and column, raised before anything is built from it."""

    def __init__(self, mark: Any, problem: str) -> None:
        super().__init__(problem)
        self.place = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        self.problem = problem


def _check_nodes(root: Any) -> None:
    """Walk the composed node graph of one document (an alias is its anchor's node again, so a
    bomb is still small here) and refuse it if it nests deeper than MAX_DEPTH, if an alias sits
    inside its own anchor, or if its aliases repeat more than MAX_ALIAS_NODES values. Iterative,
    and each node's expanded size is counted once: the walk costs what the file's text does."""
    import yaml

    size: dict[int, int] = {}  # a finished node -> how many values it stands for, written out
    open_: set[int] = set()  # the nodes on the path from the root
    repeated = 0

    def children(node: Any) -> list[Any]:
        if isinstance(node, yaml.SequenceNode):
            return list(node.value)
        if isinstance(node, yaml.MappingNode):
            return [part for pair in node.value for part in pair]
        return []

    # each frame: [node, its children, the next child's index, the size counted so far]
    stack: list[list[Any]] = [[root, children(root), 0, 1]]
    open_.add(id(root))
    while stack:
        frame = stack[-1]
        node, kids, i = frame[0], frame[1], frame[2]
        if i == len(kids):
            stack.pop()
            open_.discard(id(node))
            size[id(node)] = frame[3]
            if stack:
                stack[-1][3] += frame[3]
            continue
        frame[2] = i + 1
        kid = kids[i]
        done = size.get(id(kid))
        if done is None and type(kid) is yaml.ScalarNode:  # most nodes: no frame for them
            size[id(kid)] = 1
            frame[3] += 1
        elif done is not None:  # an alias of a finished anchor (or a merge of one)
            repeated += done
            frame[3] += done
            if repeated > MAX_ALIAS_NODES:
                raise _Refused(
                    node.start_mark,
                    f"aliases repeat more than {MAX_ALIAS_NODES} values in all (a YAML bomb?)",
                )
        elif id(kid) in open_:
            raise _Refused(node.start_mark, "an alias inside its own anchor (a value that holds "
                                            "itself)")  # fmt: skip
        elif len(stack) >= MAX_DEPTH:
            raise _Refused(kid.start_mark, f"nested deeper than {MAX_DEPTH} levels")
        else:
            open_.add(id(kid))
            stack.append([kid, children(kid), 0, 1])


def _unique_key_loader(fast: bool = True) -> type:
    """A safe loader whose mappings refuse a key given twice (PyYAML keeps the last silently):
    on libyaml's parser (`yaml.CSafeLoader`, ten times faster) when PyYAML was built with it and
    `fast`, else on the pure-Python one. The key check is the same Python code on both.

    Before anything is constructed, the composed document is checked (`_check_nodes`): not
    too deep, no alias bomb. libyaml composes in C; the pure-Python composer recurses, so it
    counts its depth as it goes (libyaml stops at 1000 levels by itself)."""
    import yaml

    base = yaml.CSafeLoader if fast and yaml.__with_libyaml__ else yaml.SafeLoader

    class UniqueKeyLoader(base):  # type: ignore[valid-type,misc]
        _depth = 0

        def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node:
            if self._depth >= MAX_DEPTH:
                raise _Refused(self.peek_event().start_mark,
                               f"nested deeper than {MAX_DEPTH} levels")  # fmt: skip
            self._depth += 1
            try:
                node: yaml.Node = super().compose_node(parent, index)
            finally:
                self._depth -= 1
            return node

        def get_single_node(self) -> yaml.Node | None:
            node: yaml.Node | None = super().get_single_node()
            if node is not None:
                _check_nodes(node)
            return node

        def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
            try:
                value: int = super().construct_yaml_int(node)
            except ValueError:  # past Python's 4300 digits
                raise yaml.constructor.ConstructorError(
                    None, None, f"a number of {len(node.value)} digits", node.start_mark
                ) from None
            return value

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
                        f"duplicate key {excerpt(key)} (first on line {earlier.start_mark.line + 1})",
                        key_node.start_mark,
                    )  # fmt: skip
            result: dict[object, object] = super().construct_mapping(node, deep)
            return result

    UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", UniqueKeyLoader.construct_yaml_int)
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


def read_text(path: str | Path) -> str:
    """A data file's text: at most MAX_YAML_BYTES, UTF-8; else a ConfigError saying which."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            data = f.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise ConfigError(p, "", f"cannot read: {exc.strerror or exc}") from None
    if len(data) > MAX_YAML_BYTES:
        raise ConfigError(p, "", f"larger than {MAX_YAML_BYTES >> 20} MB: not a data file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(
            p, f"line {line}", f"not UTF-8 text (byte 0x{data[exc.start]:02x})"
        ) from None


def load_yaml(path: str | Path) -> object:
    """Parse one YAML file: a syntax error, or a mapping key given twice, becomes a ConfigError
    naming the file, the line and column, and the problem; so does a file that is not UTF-8
    text, that nests deeper than MAX_DEPTH, or whose aliases repeat more than MAX_ALIAS_NODES
    values (refused before they are written out).

    libyaml parses; a file it refuses is parsed again by the pure-Python parser, whose words
    (and marks) every error message gives, so an error reads the same with or without libyaml."""
    import yaml

    p = Path(path)
    text = read_text(p)
    try:
        try:
            return yaml.load(text, Loader=yaml_loader())  # noqa: S506 -- a safe loader
        except yaml.YAMLError:
            pass
        return yaml.load(text, Loader=yaml_loader(fast=False))  # noqa: S506 -- a SafeLoader
    except _Refused as exc:
        raise ConfigError(p, exc.place, exc.problem) from None
    except yaml.reader.ReaderError as exc:  # a control character: binary, most likely
        line = text.count("\n", 0, exc.position) + 1
        raise ConfigError(
            p, f"line {line}", f"not YAML text: character #x{exc.character:04x} (a binary file?)"
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        place = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(p, place, f"invalid YAML: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(p, "", f"invalid YAML: {exc}") from None


def load_mapping(path: str | Path, what: str) -> dict[Any, Any]:
    """`load_yaml` of a file whose top is a mapping (`key: value` lines), as every data file of
    ktcs-bench is (`what` it is: "procedure", "lab", ...); an empty file, or one whose top is a
    list or a single value, is a ConfigError saying so."""
    doc = load_yaml(path)
    if doc is None:
        raise ConfigError(path, "", f"empty: a {what} file is a YAML mapping (key: value lines)")
    if not isinstance(doc, dict):
        raise ConfigError(
            path, "", f"a {what} file is a YAML mapping (key: value lines), not {kind_of(doc)}"
        )
    return doc


class YamlReader:
    """Checks what a declared shape leaves free in one parsed YAML file (a step's words, a
    mapping of arguments); each mistake is one ConfigError naming the file, the place (a key path)
    and what is wrong -- quoting at most an `excerpt` of a value. Shared by the loaders of
    scenario and procedure files; their shapes are converted by `schema.convert`."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, place: str, problem: str) -> ConfigError:
        from ktcs_bench.schema import located

        return located(self.path, place, problem)

    def mapping(self, obj: object, place: str) -> dict[str, Any]:
        if not isinstance(obj, dict):
            raise self.fail(place, f"expected a mapping, got {kind_of(obj)}")
        return obj

    def word(self, v: object, place: str) -> str:
        """One text value of the file (a number is taken as its digits)."""
        if not isinstance(v, (str, int)) or isinstance(v, bool):
            raise self.fail(place, f"expected text, got {kind_of(v)} {excerpt(v)}")
        return str(v)
