"""The CTC's layers import downwards only, counting imports inside functions too: the CTC device
(`emulator`) hosts the console, the console draws the CTC's model, the model reads what the Type II
server feeds it -- never the other way round."""

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


@pytest.mark.parametrize(
    ("package", "never"),
    [
        ("console", {"emulator"}),
        ("ctc", {"emulator", "console"}),
        ("type2", {"ctc", "console", "emulator"}),
        ("train", {"console", "emulator"}),
    ],
)
def test_a_layer_never_reaches_the_ones_above_it(package: str, never: set[str]) -> None:
    graph = package_imports()
    assert package in graph  # the walk saw it
    assert not reaches(graph, package) & never
