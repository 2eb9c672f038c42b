"""pytest, the runner engineers already use, runs the procedures (SPEC §12): a procedure file --
a YAML file with `steps:` in a folder named `procedures` -- is collected as one test item, run on
a fresh lab in one process on the virtual clock, as `ktcs-bench test run` runs it (the same
loader, the same runner). Its tags become marks (`pytest -m interlocking`, a hyphen read as `_`),
its requirement ids JUnit properties (`--junitxml`), a failed step the assertion message; a file
`test run` would refuse is a collection error naming file and place.

Tests written in Python get the same `LabAccess` the procedures use through the `ktcs_lab`
fixture: `ktcs_lab.run(check, lab)` runs `await check(access)` on a fresh lab in one process on
the virtual clock, or -- with `--ktcs-live LAB` -- on that running `lab up`.

Registered as a `pytest11` entry point of the package (installed: `pytest emulators/procedures`);
without the installation, `pytest -p ktcs_bench.procedure.pytest_plugin emulators/procedures`.
Each item makes its own lab, so pytest-xdist may spread them over workers (`-n 2`).
"""

from __future__ import annotations

import asyncio
import re
import tempfile
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest

from ktcs_bench.errors import ConfigError, KtcsError
from ktcs_bench.junit import REQUIREMENT

SUFFIXES = (".yaml", ".yml")
FOLDER = "procedures"
_STEPS = re.compile(r"^steps\s*:", re.M)


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("ktcs-bench", "ktcs-bench procedures")
    group.addoption("--ktcs-catalogue", metavar="FILE", default=None,
                    help="the requirements catalogue procedures' `verifies:` ids are checked "
                         "against (default: the shipped one)")  # fmt: skip
    group.addoption("--ktcs-live", metavar="LAB", default=None,
                    help="the ktcs_lab fixture attaches to this running `lab up` instead of "
                         "making a lab in the test's process")  # fmt: skip


def is_procedure_file(path: Path) -> bool:
    """A YAML file in a folder named `procedures` whose top level has `steps:` (its labs, in a
    folder of their own, are not)."""
    if path.suffix not in SUFFIXES or path.parent.name != FOLDER:
        return False
    try:
        head = path.read_text(encoding="utf-8", errors="replace")[:100_000]
    except OSError:
        return False
    return bool(_STEPS.search(head))


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> pytest.Collector | None:
    if is_procedure_file(file_path):
        item: pytest.Collector = ProcedureFile.from_parent(parent, path=file_path)
        return item
    return None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The procedures longest first (by the most lab time their steps may take), each in a place
    a procedure had: under pytest-xdist the long runs (the meet, the train run: most of the
    suite's time) start at once instead of one of them last, with the short ones filling in
    beside them. Other tests keep their order."""
    at = [i for i, item in enumerate(items) if isinstance(item, ProcedureItem)]
    ordered = sorted((items[i] for i in at), key=_lab_time, reverse=True)
    for i, item in zip(at, ordered, strict=True):
        items[i] = item


def _lab_time(item: pytest.Item) -> float:
    return float(item.procedure.most_lab_time_s) if isinstance(item, ProcedureItem) else 0.0


def mark_name(tag: str) -> str:
    """A tag as a mark's name: `approach-locking` -> `approach_locking`."""
    name = re.sub(r"\W", "_", tag)
    return name if name and not name[0].isdigit() else f"tag_{name}"


class ProcedureFile(pytest.File):
    def collect(self) -> Iterator[pytest.Item]:
        from ktcs_bench.evidence.catalogue import load_catalogue
        from ktcs_bench.procedure.model import load_procedure

        option = self.config.getoption("ktcs_catalogue", None)
        try:
            catalogue = load_catalogue(option) if option else None
            procedure = load_procedure(self.path, catalogue)
        except (ConfigError, KtcsError) as exc:
            raise self.CollectError(str(exc)) from None
        item = ProcedureItem.from_parent(self, name=procedure.id, procedure=procedure)
        for tag in procedure.tags:
            name = mark_name(tag)
            self.config.addinivalue_line("markers", f"{name}: a procedure tag")
            item.add_marker(name)
        item.user_properties.extend((REQUIREMENT, rid) for rid in procedure.verifies)
        yield item


class ProcedureFailed(Exception):
    """The procedure did not pass: the result's words are the test's failure."""


class ProcedureItem(pytest.Item):
    fixturenames: tuple[str, ...] = ()
    """None: a procedure sets its lab up itself. Plugins that read every item's fixture names as
    a test function's (labgrid's pytest plugin, on every machine the bench's test extra is
    installed on) find the empty list rather than an AttributeError."""

    def __init__(self, *, procedure: Any, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.procedure = procedure
        self.result: Any = None

    def runtest(self) -> None:
        from ktcs_bench.procedure.report import result_text
        from ktcs_bench.procedure.runner import run_procedure
        from ktcs_bench.timed.vloop import VirtualDeadlock

        lab_class = _in_process()
        with tempfile.TemporaryDirectory(prefix="ktcs-procedure-") as tmp:
            lab = lab_class(self.procedure.setup.lab, clock="virtual", out=Path(tmp))
            try:
                self.result = lab.run(lambda access: run_procedure(self.procedure, access,
                                                                   "virtual"))  # fmt: skip
            except VirtualDeadlock as exc:
                raise ProcedureFailed(f"the lab stalled: {exc}") from None
        if self.result.verdict != "pass":
            raise ProcedureFailed(f"{self.result.message}\n{result_text(self.result, False)}")

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException], style: Any = None) -> str:
        if isinstance(excinfo.value, ProcedureFailed):
            return str(excinfo.value)
        return str(super().repr_failure(excinfo))

    def reportinfo(self) -> tuple[Path, int, str]:
        return self.path, 0, f"procedure {self.procedure.id}: {self.procedure.title}"


T = TypeVar("T")


class KtcsLab:
    """What the `ktcs_lab` fixture gives a test: `run(check, lab)` awaits `check(access)` with
    a `lab.access.LabAccess` -- in one process on the virtual clock by default (the lab file or
    shipped name `lab`, files written under the test's tmp_path), on the running lab `live`
    (`--ktcs-live LAB`) otherwise, where `lab` is not used."""

    def __init__(self, live: str | None, out: Path) -> None:
        self.live = live
        self.out = out
        self.runs = 0

    def run(self, check: Callable[[Any], Awaitable[T]], lab: str = "reference") -> T:
        if self.live is not None:
            return asyncio.run(self._live(check))
        from ktcs_bench.lab.topology import load_lab, resolve_lab_path

        self.runs += 1
        out = self.out / f"lab{self.runs}"
        result: T = _in_process()(load_lab(resolve_lab_path(lab)), clock="virtual",
                                  out=out).run(check)  # fmt: skip
        return result

    async def _live(self, check: Callable[[Any], Awaitable[T]]) -> T:
        from ktcs_bench.lab.access_live import LiveLabAccess

        assert self.live is not None
        access = LiveLabAccess.attach(self.live)
        try:
            return await check(access)
        finally:
            await access.close()


@pytest.fixture
def ktcs_lab(request: pytest.FixtureRequest, tmp_path: Path) -> KtcsLab:
    """A lab for a test written in Python, reached as the procedures reach theirs."""
    return KtcsLab(request.config.getoption("ktcs_live", None), tmp_path)


def _in_process() -> Any:
    from ktcs_bench.lab.inprocess import InProcessLab  # the lab in one process, virtual clock

    return InProcessLab
