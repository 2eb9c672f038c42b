"""A device's conformance statement (ICS, the ISO 9646 "implementation conformance statement"):
what the device under test claims -- its role, the optional opcodes it supports, whether it
sends a link test, its largest frame, its timings. The suite runs the cases that apply and
reports the others as not applicable, never as passed (`not_applicable`).

    ics: ktcs-bench conformance statement
    device: ATC of station 18 (ktcs-bench emulator)
    role: atc
    profile: ktcs-type1          # optional: the role's default profile
    link_test: true              # sends LINK_TEST when idle
    opcodes: [REQUEST_ALL, ALL_INFO, CHANGE, LINK_TEST]   # optional opcodes it supports (all)
    max_frame: 1024              # Type I: the most DATA bytes of a frame it takes (the profile's)
    timings: {delta_r: 0.2, ack_timeout: 0.3, link_test_period: 1.0, t_max: 3.0, retry_count: 3}

The shape is declared once (`IcsShape`, `schema.convert`); what hangs on the profile -- an
opcode it does not have, a frame longer than it allows -- is checked here, one ConfigError naming
the file, key path and line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import msgspec
from msgspec import Meta

from ktcs_bench import kinds
from ktcs_bench.codec.profile import FrameProfile, get_profile
from ktcs_bench.conformance.model import Case
from ktcs_bench.datafiles import load_mapping
from ktcs_bench.errors import ConfigError, UsageError, excerpt
from ktcs_bench.schema import Shape, convert, finite, located

Seconds = Annotated[float, Meta(gt=0)]


class TimingsShape(Shape):
    delta_r: Seconds | None = None
    ack_timeout: Seconds | None = None
    link_test_period: Seconds | None = None  # Type I; Type II: heartbeat_period
    heartbeat_period: Seconds | None = None
    t_max: Seconds | None = None
    retry_count: Annotated[int, Meta(ge=0)] | None = None
    longest_frame: Annotated[int, Meta(ge=1)] | None = None  # DATA bytes (sizes ΔR)


class IcsShape(Shape):
    role: str
    ics: str = ""
    device: str = ""
    profile: str | None = None
    link_test: bool = True
    opcodes: tuple[str, ...] | None = None  # None: every opcode of the profile
    max_frame: Annotated[int, Meta(ge=1)] | None = None
    timings: TimingsShape = msgspec.field(default_factory=TimingsShape)


@dataclass(frozen=True)
class Ics:
    path: Path
    device: str
    role: str
    profile: str | None
    link_test: bool
    opcodes: frozenset[str] | None
    max_frame: int | None
    timings: TimingsShape

    def supports(self, opcode: str) -> bool:
        return self.opcodes is None or opcode in self.opcodes

    def not_applicable(self, case: Case) -> str | None:
        """Why `case` does not apply to the device as its statement describes it (None: it
        does)."""
        where = f"(statement {self.path.name})"
        if case.name == "link-test-timing" and not self.link_test:
            return f"the device sends no link test {where}"
        needs = NEEDS_OPCODE.get(case.name)
        if needs is not None and not self.supports(needs):
            return f"the device does not support {needs} {where}"
        return None

    def sized(self, profile: FrameProfile) -> FrameProfile:
        """The profile with the device's largest frame (Type I), as the suite judges it."""
        import dataclasses

        if self.max_frame is None or profile.protocol != "type1":
            return profile
        return dataclasses.replace(profile, max_len=self.max_frame + profile.fixed_counted)


NEEDS_OPCODE = {"request-all": "REQUEST_ALL", "t2-request-all": "REQUEST_ALL",
                "t2-seq-gap": "REQUEST_ALL"}  # fmt: skip
"""The cases that exercise an opcode a device may leave out, and that opcode."""


def default_profile(role: str) -> str:
    return "ktcs-type2" if role == kinds.CTC else "ktcs-type1"


def load_ics(path: str | Path) -> Ics:
    p = Path(path)
    doc = convert(load_mapping(p, "conformance statement"), IcsShape, p)
    finite(doc, p)
    if doc.role not in kinds.CONFORMANCE_KINDS:
        raise located(p, "role", f"{excerpt(doc.role)} is not a role of the suite "
                      f"({', '.join(kinds.CONFORMANCE_KINDS)})")  # fmt: skip
    name = doc.profile or default_profile(doc.role)
    try:
        profile = get_profile("ktcs-type2" if name == "type2-tls" else name)
    except (UsageError, ConfigError) as exc:
        raise located(p, "profile", str(exc)) from None
    for i, op in enumerate(doc.opcodes or ()):
        if op.upper() not in profile.opcodes.by_name:
            raise located(p, f"opcodes[{i}]", f"{excerpt(op)} is no opcode of {profile.name} "
                          f"({', '.join(profile.opcodes.by_name)})")  # fmt: skip
    if doc.max_frame is not None and doc.max_frame > profile.max_data:
        raise located(p, "max_frame", f"{doc.max_frame} DATA bytes: more than {profile.name} "
                      f"frames carry ({profile.max_data})")  # fmt: skip
    opcodes = None if doc.opcodes is None else frozenset(o.upper() for o in doc.opcodes)
    return Ics(p, doc.device, doc.role, doc.profile, doc.link_test, opcodes, doc.max_frame,
               doc.timings)  # fmt: skip
