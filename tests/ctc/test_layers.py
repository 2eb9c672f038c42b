"""The layers import downwards only, counting imports inside functions too: the CTC device
(`emulator`) hosts the console, the console draws the CTC's model, the model reads what the Type II
server feeds it -- never the other way round. And the sans-I/O cores reach no I/O or clock module
at all, through any chain of imports."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import ktcs_bench

ROOT = Path(ktcs_bench.__file__).resolve().parent


def package_imports() -> dict[str, set[str]]:
    """package -> the ktcs_bench packages any of its modules imports, wherever the import is."""
    out: dict[str, set[str]] = {}
    for path in ROOT.rglob("*.py"):
        package = path.relative_to(ROOT).parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                parts = name.split(".")
                if parts[0] == "ktcs_bench" and len(parts) > 1 and parts[1] != package:
                    out.setdefault(package, set()).add(parts[1])
    return out


def reaches(graph: dict[str, set[str]], start: str) -> set[str]:
    seen: set[str] = set()
    todo = [start]
    while todo:
        for nxt in graph.get(todo.pop(), set()) - seen:
            seen.add(nxt)
            todo.append(nxt)
    return seen


def test_no_part_of_the_bench_reaches_itself_through_another() -> None:
    """No import cycle between the packages of ktcs_bench (issue 14), function-level imports
    counted: a part that imports another never gets imported back by it, however indirectly."""
    graph = package_imports()
    assert {p: sorted(reaches(graph, p) & {p}) for p in graph if p in reaches(graph, p)} == {}


@pytest.mark.parametrize(
    ("package", "never"),
    [
        ("console", {"emulator"}),
        ("ctc", {"emulator", "console"}),
        ("type2", {"ctc", "console", "emulator", "transport"}),
        ("train", {"console", "emulator"}),
        ("faults", {"transport", "tap", "type1", "type2", "emulator"}),
        ("transport", {"tap", "emulator", "lab", "console", "threats", "cli"}),
        ("tap", {"emulator", "lab", "console", "threats", "cli"}),  # type2: module by module
        ("replay", {"cli", "lab", "emulator", "console"}),
    ],
)
def test_a_layer_never_reaches_the_ones_above_it(package: str, never: set[str]) -> None:
    graph = package_imports()
    assert package in graph  # the walk saw it
    assert not reaches(graph, package) & never


TYPE2_ADAPTERS = ("ktcs_bench.transport.type2_pump", "ktcs_bench.transport.ctc_server",
                  "ktcs_bench.transport.ixl_client")  # fmt: skip
"""Type II's asyncio adapters: `transport`'s modules, so `transport` as a package reaches `type2`."""


def test_the_tap_loads_no_type2_module() -> None:
    """The tap is below Type II: no module of it loads a Type II one, nor Type II's adapters in
    `transport` (module by module, since `transport` as a whole holds those adapters)."""
    graph = module_imports()
    taps = [m for m in graph if m.startswith("ktcs_bench.tap.")]
    assert len(taps) > 3  # the walk found the tap's modules
    reached = set().union(*(reaches(graph, m) for m in taps))
    assert "ktcs_bench.transport.net" in reached  # the walk follows the tap into transport
    assert sorted(m for m in reached
                  if m.startswith("ktcs_bench.type2") or m in TYPE2_ADAPTERS) == []  # fmt: skip


def test_a_cli_subcommand_imports_no_other() -> None:
    """Each subcommand is a front over the library: its module imports no other subcommand's
    (replay once took monitor's printer and decode's profile vote); what two share is library."""
    graph = module_imports()
    fronts = {m for m in graph if m.startswith("ktcs_bench.cli.")} - {
        "ktcs_bench.cli._common", "ktcs_bench.cli.main"}  # fmt: skip
    assert {"ktcs_bench.cli.replay", "ktcs_bench.cli.monitor", "ktcs_bench.cli.decode"} <= fronts
    assert {m: sorted(graph[m] & fronts - {m}) for m in fronts if graph[m] & fronts - {m}} == {}


# -- the sans-I/O cores --------------------------------------------------------------------------

IO_AND_CLOCKS = {"asyncio", "time", "socket", "serial", "threading", "select", "selectors", "ssl",
                 "subprocess", "signal"}  # fmt: skip
"""What a sans-I/O core must never import, even through another module: I/O and clocks."""

CORES = ("codec", "station_codes", "binding", "type1", "type2", "faults", "station", "ixl", "field",
         "atc", "train", "scenario",
         "timed", "tap.core", "tap.control", "tap.recorder", "ctc.model", "ctc.tables",
         "ctc.log", "ctc.ars", "ctc.describer")  # fmt: skip
"""The cores fed bytes/events and an explicit `now` (a package: every module in it)."""

ADAPTERS = {"ktcs_bench.timed.aio", "ktcs_bench.timed.vloop"}
"""Modules inside a core package that are its drivers' adapters, not the core."""


def module_imports() -> dict[str, set[str]]:
    """module -> every module its import statements load (wherever they stand in the file,
    and the packages above each: importing a.b.c runs a/__init__ and a/b/__init__ first)."""
    out: dict[str, set[str]] = {}
    for path in ROOT.rglob("*.py"):
        parts = ("ktcs_bench", *path.relative_to(ROOT).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if is_package else parts)
        here = module if is_package else module.rpartition(".")[0]
        loads: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here.split(".")[: len(here.split(".")) - node.level + 1]
                    base = ".".join([*up, base] if base else up)
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            for name in names:
                bits = name.split(".")
                loads.update(".".join(bits[: k + 1]) for k in range(len(bits)))
        out[module] = loads
    if "ktcs_bench" in out:
        out["ktcs_bench"] = set()  # its __init__ is ours to read: it imports nothing of note
    return out


def io_reached(graph: dict[str, set[str]], start: str) -> list[list[str]]:
    """Import chains from `start` to a module of `IO_AND_CLOCKS`."""
    found: list[list[str]] = []
    seen = {start}
    todo = [[start]]
    while todo:
        chain = todo.pop()
        for name in sorted(graph.get(chain[-1], set())):
            if name in IO_AND_CLOCKS:
                found.append([*chain, name])
            elif name in graph and name not in seen:
                seen.add(name)
                todo.append([*chain, name])
    return found


def test_the_sans_io_cores_import_no_io_or_clock_module() -> None:
    graph = module_imports()
    cores = [
        m
        for m in graph
        if any(m == f"ktcs_bench.{c}" or m.startswith(f"ktcs_bench.{c}.") for c in CORES)
        and m not in ADAPTERS
    ]
    assert len(cores) > 40  # the walk found the cores' modules
    bad = {m: io_reached(graph, m) for m in cores}
    assert not {m: chains[0] for m, chains in bad.items() if chains}


# -- the device kinds have one home ---------------------------------------------------------------

KIND_TABLE = "kinds.py"
"""The one table of the device kinds (`ktcs_bench.kinds`): the only module naming them."""

GRAMMAR = {
    "procedure/steps.py": "a procedure's step words (`- ctc: route set ...`, `- train: T1 ...`)",
    "procedure/expect.py": "a procedure's expectation words (`ixl 18 route ...`, `ctc 18 signal`)",
    "cli/ctc.py": "the `ktcs-bench ctc` command's name",
}
"""Modules where a kind's word is user-facing grammar, spelled as the user types it: renaming a
kind must not silently change what users' procedures and command lines say."""


def kind_words(path: Path) -> dict[str, int]:
    """The string constants of a module equal to a kind's name (docstrings aside), counted."""
    from ktcs_bench import kinds

    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {
        id(st.value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        for st in node.body
        if isinstance(st, ast.Expr) and isinstance(st.value, ast.Constant)
    }
    out: dict[str, int] = {}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Constant)
            and node.value in kinds.KINDS
            and id(node) not in docstrings
        ):
            out[node.value] = out.get(node.value, 0) + 1
    return out


def test_the_device_kinds_are_named_only_in_their_table() -> None:
    """Issue 22 part 1: a kind -- ctc, ixl, atc, trackside, trackcircuit, train -- is spelled in
    `ktcs_bench.kinds` and read from it everywhere else (its constants, its rows), so a new kind
    is a row there, not edits across the tree; only the grammar modules spell the words users
    type."""
    found = {
        str(path.relative_to(ROOT)): words
        for path in sorted(ROOT.rglob("*.py"))
        if (words := kind_words(path))
    }
    assert KIND_TABLE in found  # the scan sees the table's own spelling
    assert len(GRAMMAR) <= 3
    assert {m: w for m, w in found.items() if m != KIND_TABLE and m not in GRAMMAR} == {}


def test_every_kind_builds_through_its_row() -> None:
    """Each row's builder names a function that exists (it is imported only when a device of
    that kind is built, so the table stays at the bottom of the layers)."""
    import importlib

    from ktcs_bench import kinds

    for kind in kinds.KINDS.values():
        module, _, func = kind.builder.partition(":")
        assert callable(getattr(importlib.import_module(module), func)), kind.name
    assert package_imports().get("kinds", set()) == set()  # the table imports nothing of ours
