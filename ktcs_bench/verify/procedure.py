"""A violation's input sequence written as a procedure file for `ktcs-bench test run` on the
reference lab without trains (`emulators/procedures/labs/quiet.yaml`).

What the search drives directly becomes the lab's words: route and point controls at the CTC
(with the answer the core gave: `refused: REASON`), the local panel, faults (point detection, a
track circuit failed occupied, a link cut and restored, clear), trains placed and run track circuit
by track circuit, and each timer as a wait for its time. The neighbour's moves cannot be driven in
a lab -- its own IXL makes them -- except its operator asking for the permission (`ctc: direction`):
the others are written as notes. A violated signal check ends, after 2 s for the links, in `expect: ixl ST signal S is R` held
for 5 s,
which the defective lab then fails and a sound one passes.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import yaml

from ktcs_bench.datafiles import data_dir
from ktcs_bench.procedure.steps import CTC_STEP, TRAIN_STEP
from ktcs_bench.station.model import Line
from ktcs_bench.verify.explore import Bound, Violation, start

QUIET_LAB = ("procedures", "labs", "quiet.yaml")


REQUIREMENTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("§6.2 (1)", ("IXL-INV-01",)),
    ("§6.2 (2)", ("IXL-INV-02",)),
    ("§6.2 (3, 4)", ("IXL-INV-03", "IXL-INV-04")),
    ("§6.2 (5)", ("IXL-INV-05",)),
    ("§6.6", ("IXL-INV-05",)),
    ("§6.2 (6)", ("IXL-INV-06",)),
    ("§6.7", ("SYS-SAFE-03",)),
)
"""The requirements catalogue's ids (emulators/requirements) each invariant the search checks is."""


def requirements(what: list[str]) -> list[str]:
    """The catalogue ids of the invariants a violation broke, for the procedure's `verifies:`."""
    out: list[str] = []
    for text in what:
        for clause, ids in REQUIREMENTS:
            if clause in text:
                out += [i for i in ids if i not in out]
    return out


def procedure_steps(line: Line, bound: Bound, violation: Violation) -> list[dict[str, Any]]:
    """The violation's inputs replayed on a fresh core, each as a procedure step."""
    world = start(line, violation.station, bound)
    st = violation.station
    station = line.station(st)
    names: dict[int, str] = {}
    out: list[dict[str, Any]] = []
    for step in violation.steps:
        kind, args = step[0], step[1:]
        trains_before = list(world.trains)
        due = world.rig.next_deadline()
        now = world.now
        answer = world.apply(step)
        entry: dict[str, Any]
        if kind == "timer" and due is not None:
            wait = max(math.ceil((due - now) * 10) / 10, 0.1)
            entry = {"wait": f"{wait:g}s", "note": "a timer runs out (the next deadline)"}
        elif kind in ("route", "cancel"):
            r = station.route(args[0])
            verb = "set" if kind == "route" else "cancel"
            entry = {CTC_STEP: f"route {verb} {st} {r.entry} {r.exit}"}
        elif kind == "point":
            entry = {CTC_STEP: f"point {args[1]} {st} {args[0]}"}
        elif kind == "signal":
            entry = {CTC_STEP: f"signal {args[1]} {st} {args[0]}"}
        elif kind == "mode":
            entry = {CTC_STEP: f"mode center {st}"} if args[0] == "center" else {
                "local": f"{st} {args[0]}"}  # fmt: skip
        elif kind == "enter":
            train = world.trains[-1]
            names[id(train)] = f"V{len(names) + 1}"
            track = "" if args[1] == "-" else f" track {args[1]}"
            entry = {TRAIN_STEP: f"{names[id(train)]} place {args[0]}{track} {args[2]}"}
        elif kind == "move":
            train = trains_before[int(args[0])]
            name = names.setdefault(id(train), f"V{len(names) + 1}")
            if train in world.trains:
                entry = {TRAIN_STEP: f"{name} run to {train.tc}"}
            else:
                entry = {TRAIN_STEP: f"{name} remove", "note": "it runs off the station's rails"}
        elif kind == "detection_lost":
            entry = {"fault": f"point {st} {args[0]} detection"}
        elif kind == "tc_failed":
            entry = {"fault": f"tc {args[0]} failed_occupied"}
        elif kind == "repair":
            entry = {"fault": "clear"}
        elif kind in ("link_down", "link_up"):
            entry = {
                "fault": f"link st{st}-{args[0]} {'cut' if kind == 'link_down' else 'restore'}"
            }
        elif kind in ("neighbour_link_down", "neighbour_link_up"):
            verb = "cut" if kind == "neighbour_link_down" else "restore"
            entry = {"fault": f"link iv{args[0]} {verb}"}
        elif kind == "neighbour_asks":
            iv = world.interval(args[0])
            other = iv.east if iv.west == st else iv.west
            entry = {CTC_STEP: f"direction {other} {args[0]}"}
        else:
            entry = {"wait": "0.5s", "note": f"the neighbour across {args[0]}: "
                     f"{kind.removeprefix('neighbour_').replace('_', ' ')} (its own IXL decides "
                     "in the lab; not driven)"}  # fmt: skip
        if answer is not None and not answer.accepted and CTC_STEP in entry:
            entry["refused"] = answer.reason.text
        out.append(entry)
    what = "; ".join(violation.what)
    m = re.search(r"signal (\S+) shows", what)
    if m:
        out.append({"wait": "2s", "note": "what the last step changed reaches the IXL over "
                    "its links (in the search it is there at once)"})  # fmt: skip
        out.append({"expect": f"ixl {st} signal {m.group(1)} is R", "holds": "5s",
                    "note": f"the search found: {what}"})  # fmt: skip
    elif out:
        out[-1]["note"] = f"here the search found: {what}"
    return out


def write_procedure(
    line: Line, bound: Bound, violation: Violation, out_dir: Path, index: int
) -> Path:
    """DIR/verify_STATION_N.yaml; the path written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"verify_{violation.station}_{index}.yaml"
    lab = data_dir("emulators").joinpath(*QUIET_LAB)
    doc = {
        "id": f"verify-{violation.station}-{index}",
        "title": f"ixl verify: {'; '.join(violation.what)}",
        "verifies": requirements(violation.what),
        "tags": ["verify", "counterexample", f"station{violation.station}"],
        "setup": {"lab": os.path.relpath(lab, out_dir.resolve())},
        "steps": procedure_steps(line, bound, violation),
    }
    path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return path
