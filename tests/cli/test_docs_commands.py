"""Every `ktcs-bench ...` command line the docs quote (docs/*.md and the README, in code blocks and
in inline code) is one the command takes today: its subcommands exist, every option it names is
an option of that subcommand, and a concrete line (no `[...]`, `a|b` or `...` of a synopsis) parses
with the real parser. And a line runs as written in a shell: no unquoted `>` inside a word (a
tap direction `ixl->atc` typed as it stands sends the output to a file `atc`). So the docs cannot
go stale silently when a command changes."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest

from ktcs_bench.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[2]
DOCS = [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]
PLACEHOLDER = re.compile(r"[A-Z][A-Z0-9_]*|\.\.\.|…")  # KIND, FILE, ...: a synopsis's words
SHELL_STOP = {"|", ">", ">>", "&&", ";", "&", "2>&1"}


def quoted_commands(path: Path) -> Iterator[tuple[int, str]]:
    """(line number, command) of every `ktcs-bench` command line quoted in a Markdown file."""
    lines = path.read_text(encoding="utf-8").splitlines()
    fence, i = False, 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("```"):
            fence = not fence
        elif fence:
            m = re.search(r"(?:^|\s)(ktcs-bench(?:\s.*)?)$", line)
            if m and not line.lstrip().startswith("#"):
                cmd, first = m.group(1), i
                while cmd.rstrip().endswith("\\") and i + 1 < len(lines):  # continued lines
                    i += 1
                    cmd = cmd.rstrip()[:-1] + " " + lines[i].strip()
                for part in re.split(r"\s(?:;|&&)\s+(?=ktcs-bench\b)", cmd):
                    yield first + 1, part
        else:
            for m in re.finditer(r"`(ktcs-bench(?:\s[^`]*)?)`", line):
                yield i + 1, m.group(1).replace("\\|", "|")  # `a\|b` in a table cell
        i += 1


def _subcommands(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:  # type: ignore[type-arg]
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def problems(cmd: str) -> list[str]:
    """What in a quoted command line the command does not take (empty: it is fine)."""
    found = unquoted_redirects(cmd)
    words = shlex.split(cmd, comments=True)
    for k, w in enumerate(words):
        if w in SHELL_STOP:
            words = words[:k]
            break
    words = words[1:]  # after ktcs-bench
    top = build_parser(next((w for w in words if not w.startswith("-")), None))
    parser, path, k = top, ["ktcs-bench"], 0
    while k < len(words) and not words[k].startswith("-"):
        sub = _subcommands(parser)
        if sub is None:
            break
        if words[k] in sub.choices:
            parser = sub.choices[words[k]]
            path.append(words[k])
            k += 1
        elif PLACEHOLDER.fullmatch(words[k].strip("[]")):
            return found  # `ktcs-bench emulator KIND ...`: a synopsis of every kind
        else:
            return [*found, f"'{' '.join(path)}' has no subcommand {words[k]!r}"]
    known = {o for a in [*parser._actions, *top._actions] for o in a.option_strings}
    for w in words[k:]:
        for part in re.split(r"[\[\]|]", w):  # `[--json]`, `--virtual|--live`
            name = part.split("=", 1)[0]
            if name.startswith("-") and len(name) > 1 and not re.match(r"-\d", name):
                if name not in known:
                    found.append(f"'{' '.join(path)}' has no option {name}")
    if found or re.search(r"[\[\]|…]|\.\.\.", cmd):
        return found  # a synopsis: the names are checked, its alternatives cannot be parsed
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            top.parse_args(words)
    except SystemExit as exc:
        if exc.code not in (0, None):
            message = err.getvalue().strip().splitlines()[-1]
            bad = re.search(r"invalid .*(?:value|choice): '([^']*)'", message)
            named = "expected one argument" in message and words[-1].startswith("-")
            placeholder = bad is not None and PLACEHOLDER.fullmatch(bad.group(1)) is not None
            # a command named without the arguments it needs (`ktcs-bench line generate`), an
            # option named alone, a placeholder value (`--for SECONDS`) are what prose does
            if not ("required" in message or named or placeholder):
                found.append(message)
    return found


def unquoted_redirects(cmd: str) -> list[str]:
    """`>` glued to a word outside quotes (`ixl->atc`): the shell redirects there."""
    out, quote = [], ""
    for i, c in enumerate(cmd):
        if quote:
            quote = "" if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == ">" and i > 0 and not cmd[i - 1].isspace() and cmd[i - 1] not in "2&>":
            word = cmd[: i + 1].split()[-1] + cmd[i + 1 :].split(maxsplit=1)[0]
            out.append(f"{word!r}: an unquoted '>' in a shell command line redirects there")
    return out


COMMANDS = [
    (f"{doc.relative_to(ROOT)}:{n}", cmd) for doc in DOCS for n, cmd in quoted_commands(doc)
]


def test_the_docs_quote_command_lines() -> None:
    """The scan finds what it is for (a broken scan must not pass every doc by finding nothing)."""
    assert len(COMMANDS) > 60
    assert {where.split(":")[0] for where, _ in COMMANDS} >= {"README.md", "docs/captures.md"}


@pytest.mark.parametrize(("where", "cmd"), COMMANDS, ids=[w for w, _ in COMMANDS])
def test_a_command_line_quoted_in_the_docs_is_one_the_command_takes(where: str, cmd: str) -> None:
    assert problems(cmd) == [], f"{where}: {cmd}"


@pytest.mark.parametrize(
    "cmd",
    [
        "ktcs-bench lab simulat --for 10",  # a subcommand that is not there
        "ktcs-bench lab up --in-proces",  # an option that is not there
        "ktcs-bench lab simulate [LAB.yaml] --speed X",  # ... in a synopsis too
        "ktcs-bench line generate --stations 3 --out d extra",  # a word it does not take
        "ktcs-bench tap fault st18 drop-frame ixl->atc",  # runs as a redirect in a shell
    ],
)
def test_the_check_refuses_a_stale_command_line(cmd: str) -> None:
    assert problems(cmd) != []
