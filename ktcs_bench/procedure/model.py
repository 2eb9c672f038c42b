"""The procedure file (YAML), read and checked before anything runs; every mistake is one
ConfigError naming the file, the step (or key) and what is wrong.

    id: route-set-0111
    title: A route set at the CTC clears its signal and steps the codes
    verifies: [IXL-ROUTE-01, CTC-VIEW-01]   # requirement ids of the catalogue
    tags: [route, ctc]
    setup:
      lab: reference              # a lab of emulators/labs/, or a lab file beside this one
      trains:                     # trains the procedure places and moves itself
        - {id: T1, head: TC1851, length_m: 40}
      modes: {18: center}         # each station brought to this mode first
      ars: false                  # automatic route setting (a CTC that has it)
      restart: [train1]           # devices restarted first (a train device back at its start)
    steps:
      - ctc: route set 18 S1 S11
      - expect: ctc 18 signal 01 is not R
        within: 10s
    always:                       # expectations that hold at every sample, steps or not
      - ixl 20 signal 21 is R
      - lab invariants hold       # the lab safety invariants (docs/system_safety.md)

The top level and `setup:` are declared in `shapes` (a key no reader knows is refused with its
line); the step kinds are in `steps`, the expectation words in `expect`. `verifies:` names
requirement ids of the catalogue (`evidence.catalogue`); an id it does not hold is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from ktcs_bench import kinds
from ktcs_bench.argtypes import say_seconds
from ktcs_bench.datafiles import YamlReader, load_mapping
from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.evidence.catalogue import Catalogue, shipped_catalogue
from ktcs_bench.lab.topology import Lab, load_lab, resolve_lab_path
from ktcs_bench.procedure.expect import Expectation, parse_expectation
from ktcs_bench.procedure.names import LabNames, StepError
from ktcs_bench.procedure.shapes import ProcedureShape, Texts
from ktcs_bench.procedure.steps import (
    KINDS,
    MAX_DURATION_S,
    ExpectStep,
    Ghost,
    Step,
    WaitStep,
    parse_step,
)
from ktcs_bench.schema import READER, convert, finite, located

MODES = ("center", "local")


@dataclass(frozen=True)
class Setup:
    lab: Lab
    trains: tuple[Ghost, ...] = ()
    modes: dict[int, str] = field(default_factory=dict)
    ars: bool | None = None  # None: as the lab has it
    restart: tuple[str, ...] = ()  # devices restarted first (a train back at its start)


@dataclass(frozen=True)
class Procedure:
    path: Path
    id: str
    title: str
    verifies: tuple[str, ...]
    tags: tuple[str, ...]
    setup: Setup
    steps: tuple[Step, ...]
    names: LabNames
    always: tuple[Expectation, ...] = ()  # hold at every sample of the run

    @property
    def most_lab_time_s(self) -> float:
        """The most lab time its steps may take (their waits, `within:` and `holds:`): how long
        a run may be, for ordering the longest first."""
        return sum(_longest(s) for s in self.steps)

    @property
    def checks_invariants(self) -> bool:
        """An expectation of it (in `always:` or a step) is `lab invariants hold`: the run looks
        at the lab's safety invariants at every sample."""
        steps = (getattr(s, "expectation", None) for s in self.steps)
        return any(e is not None and e.invariants for e in (*self.always, *steps))

    @property
    def devices(self) -> set[str]:
        """Every device the steps address or read."""
        out: set[str] = set(self.setup.restart)
        for kept in self.always:
            out.update(kept.devices)
        for s in self.steps:
            exp = getattr(s, "expectation", None)
            out.update(exp.devices if exp is not None else ())
            for attr in ("device", kinds.CTC, "name"):
                value = getattr(s, attr, None)
                if isinstance(value, str) and value in self.setup.lab.devices:
                    out.add(value)
        return out


def _texts(value: Texts) -> tuple[str, ...]:
    """One text or a list of them, as texts."""
    return (str(value),) if isinstance(value, (str, int)) else tuple(str(v) for v in value)


def _longest(step: Step) -> float:
    """The most lab time one step may take waiting: its `wait:`, `within:` or `holds:`."""
    if isinstance(step, WaitStep):
        return step.seconds
    if isinstance(step, ExpectStep):
        return step.holds if step.holds is not None else step.within
    return 0.0


def _lab(r: YamlReader, path: Path, word: str) -> Lab:
    beside = path.parent / word
    candidate = beside if beside.suffix in (".yaml", ".yml") and beside.is_file() else None
    try:
        return load_lab(candidate or resolve_lab_path(word))
    except ConfigError as exc:
        said = str(exc)  # names the lab file: the word again only where it is a shipped name
        raise r.fail(
            "setup.lab", said if said.startswith(word) else f"{excerpt(word)}: {said}"
        ) from None
    except UsageError as exc:
        raise r.fail("setup.lab", str(exc)) from None


def _verifies(doc: ProcedureShape, p: Path, catalogue: Catalogue | None) -> tuple[str, ...]:
    """The requirement ids `verifies:` names, each one in the catalogue."""
    ids = _texts(doc.verifies)
    cat = catalogue if catalogue is not None else shipped_catalogue()
    for i, rid in enumerate(ids):
        if rid not in cat:
            place = f"verifies[{i}]" if isinstance(doc.verifies, tuple) else "verifies"
            raise located(p, place, f"{excerpt(rid)} is not a requirement of the catalogue "
                          f"{cat.path} (an id such as {next(iter(cat.requirements))}; free "
                          "text belongs in title: or a step's note:)")  # fmt: skip
    return ids


def load_procedure(path: str | Path, catalogue: Catalogue | None = None) -> Procedure:
    """The procedure at `path`, checked whole before anything runs; its `verifies:` ids against
    `catalogue` (None: the shipped one)."""
    p = Path(path)
    r = YamlReader(p)
    doc = convert(load_mapping(p, "procedure"), ProcedureShape, p, style=READER)
    finite(doc, p, style=READER)
    verifies = _verifies(doc, p, catalogue)
    setup_m = doc.setup
    lab = _lab(r, p, str(setup_m.lab))
    try:
        line = lab.load_line()
    except ConfigError as exc:
        raise r.fail("setup.lab", f"its line: {exc}") from None
    names = LabNames(lab, line)
    ghosts: list[Ghost] = []
    for i, tm in enumerate(setup_m.trains):
        place = f"setup.trains[{i}]"
        train = str(tm.id)
        if names.train_device(train) is not None or train in {g.train for g in ghosts}:
            raise r.fail(f"{place}.id", f"train {train} is there already")
        head_word = str(tm.head)
        try:
            head = float(head_word)
        except ValueError:
            try:
                tc = names.track_circuit(head_word)
            except StepError as exc:
                raise r.fail(f"{place}.head", str(exc)) from None
            head = (tc.from_m + tc.to_m) / 2
        ghosts.append(Ghost(train, head, tm.length_m, str(tm.track)))
        names.trains.add(train)
    modes = {}
    for key, mode in setup_m.modes.items():
        try:
            st = names.station(str(key))
        except StepError as exc:
            raise r.fail(f"setup.modes.{key}", str(exc)) from None
        if mode not in MODES:
            raise r.fail(f"setup.modes.{key}", f"center or local, not {excerpt(mode)}")
        modes[st] = str(mode)
    restart = []
    for i, word in enumerate(setup_m.restart):
        try:
            restart.append(names.device(str(word)))
        except StepError as exc:
            raise r.fail(f"setup.restart[{i}]", str(exc)) from None
    steps = []
    raw_steps = doc.steps
    if not raw_steps:
        raise r.fail("steps", "a procedure has at least one step")
    for i, raw in enumerate(raw_steps, start=1):
        try:
            steps.append(parse_step(i, raw, names))
        except StepError as exc:
            kind = next((k for k in raw if k in KINDS), None) if isinstance(raw, dict) else None
            raise r.fail(f"step {i}" + (f" ({kind})" if kind else ""), str(exc)) from None
    always = []
    for i, text in enumerate(doc.always):
        try:
            exp = parse_expectation(str(text), names)
        except StepError as exc:
            raise r.fail(f"always[{i}]", str(exc)) from None
        if exp.predicate.op in ("occurs", "absent"):
            raise r.fail(f"always[{i}]", "always: holds of a state, not of an event or a "
                         "frame (those are looked for after an action)")  # fmt: skip
        always.append(exp)
    total = sum(_longest(s) for s in steps)  # Procedure.most_lab_time_s
    if total > MAX_DURATION_S:
        raise r.fail(
            "steps",
            f"the waits, within: and holds: add up to {say_seconds(total)}; a procedure "
            f"takes at most {say_seconds(MAX_DURATION_S)} of lab time",
        )
    return Procedure(
        path=p,
        id=p.stem if doc.id is msgspec.UNSET else str(doc.id),
        title=p.stem if doc.title is msgspec.UNSET else str(doc.title),
        verifies=verifies,
        tags=_texts(doc.tags),
        setup=Setup(lab, tuple(ghosts), modes, setup_m.ars, tuple(restart)),
        steps=tuple(steps),
        names=names,
        always=tuple(always),
    )
