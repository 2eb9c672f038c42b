"""The procedure file (YAML), read and checked before anything runs; every mistake is one
ConfigError naming the file, the step (or key) and what is wrong.

    id: route-set-0111
    title: A route set at the CTC clears its signal and steps the codes
    verifies: ["SPEC §6.2 route setting", "seed 004 §3"]
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

The step kinds are in `steps`, the expectation words in `expect`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ktcs_bench import kinds
from ktcs_bench.argtypes import say_seconds
from ktcs_bench.datafiles import YamlReader, load_mapping
from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.lab.topology import Lab, load_lab, resolve_lab_path
from ktcs_bench.procedure.names import LabNames, StepError
from ktcs_bench.procedure.steps import (
    KINDS,
    MAX_DURATION_S,
    ExpectStep,
    Ghost,
    Step,
    WaitStep,
    parse_step,
)

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

    @property
    def devices(self) -> set[str]:
        """Every device the steps address or read."""
        out: set[str] = set(self.setup.restart)
        for s in self.steps:
            exp = getattr(s, "expectation", None)
            out.update(exp.devices if exp is not None else ())
            for attr in ("device", kinds.CTC, "name"):
                value = getattr(s, attr, None)
                if isinstance(value, str) and value in self.setup.lab.devices:
                    out.add(value)
        return out


def _texts(r: YamlReader, doc: dict[str, Any], key: str) -> tuple[str, ...]:
    value = doc.get(key, [])
    if isinstance(value, (str, int)) and not isinstance(value, bool):
        return (str(value),)
    return tuple(r.word(v, f"{key}[{i}]") for i, v in enumerate(r.seq(value, key)))


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


def load_procedure(path: str | Path) -> Procedure:
    p = Path(path)
    r = YamlReader(p)
    doc = load_mapping(p, "procedure")
    r.known(doc, {"id", "title", "verifies", "tags", "setup", "steps"}, "")
    setup_m = r.mapping(doc.get("setup", {}), "setup")
    r.known(setup_m, {"lab", "trains", "modes", "ars", "restart"}, "setup")
    lab = _lab(r, p, r.text(setup_m, "lab", "setup", default="reference"))
    try:
        line = lab.load_line()
    except ConfigError as exc:
        raise r.fail("setup.lab", f"its line: {exc}") from None
    names = LabNames(lab, line)
    ghosts: list[Ghost] = []
    for i, t in enumerate(r.seq(setup_m.get("trains", []), "setup.trains")):
        place = f"setup.trains[{i}]"
        tm = r.mapping(t, place)
        r.known(tm, {"id", "head", "length_m", "track"}, place)
        train = r.text(tm, "id", place)
        if names.train_device(train) is not None or train in {g.train for g in ghosts}:
            raise r.fail(f"{place}.id", f"train {train} is there already")
        head_word = r.text(tm, "head", place)
        try:
            head = float(head_word)
        except ValueError:
            try:
                tc = names.track_circuit(head_word)
            except StepError as exc:
                raise r.fail(f"{place}.head", str(exc)) from None
            head = (tc.from_m + tc.to_m) / 2
        length = r.num(tm, "length_m", place, default=40.0, minimum=1.0)
        ghosts.append(Ghost(train, head, length, r.text(tm, "track", place, default="1")))
        names.trains.add(train)
    modes = {}
    for key, mode in r.mapping(setup_m.get("modes", {}), "setup.modes").items():
        try:
            st = names.station(str(key))
        except StepError as exc:
            raise r.fail(f"setup.modes.{key}", str(exc)) from None
        if mode not in MODES:
            raise r.fail(f"setup.modes.{key}", f"center or local, not {excerpt(mode)}")
        modes[st] = str(mode)
    ars = setup_m.get("ars")
    if ars is not None and not isinstance(ars, bool):
        raise r.fail("setup.ars", f"expected true or false, got {excerpt(ars)}")
    restart = []
    for i, word in enumerate(r.seq(setup_m.get("restart", []), "setup.restart")):
        try:
            restart.append(names.device(r.word(word, f"setup.restart[{i}]")))
        except StepError as exc:
            raise r.fail(f"setup.restart[{i}]", str(exc)) from None
    steps = []
    raw_steps = r.seq(doc.get("steps"), "steps")
    if not raw_steps:
        raise r.fail("steps", "a procedure has at least one step")
    for i, raw in enumerate(raw_steps, start=1):
        try:
            steps.append(parse_step(i, raw, names))
        except StepError as exc:
            kind = next((k for k in raw if k in KINDS), None) if isinstance(raw, dict) else None
            raise r.fail(f"step {i}" + (f" ({kind})" if kind else ""), str(exc)) from None
    total = sum(_longest(s) for s in steps)
    if total > MAX_DURATION_S:
        raise r.fail(
            "steps",
            f"the waits, within: and holds: add up to {say_seconds(total)}; a procedure "
            f"takes at most {say_seconds(MAX_DURATION_S)} of lab time",
        )
    return Procedure(
        path=p,
        id=r.text(doc, "id", "", default=p.stem),
        title=r.text(doc, "title", "", default=p.stem),
        verifies=_texts(r, doc, "verifies"),
        tags=_texts(r, doc, "tags"),
        setup=Setup(lab, tuple(ghosts), modes, ars, tuple(restart)),
        steps=tuple(steps),
        names=names,
    )
