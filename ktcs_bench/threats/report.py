"""A threat's result and the campaign's reports: a Markdown table, JSON, and a coloured summary."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import TypedDict

from ktcs_bench.junit import REQUIREMENT

REQUIREMENTS: dict[str, tuple[str, ...]] = {
    "repetition": ("EN50159-REPEAT-01", "T1-ARQ-04"),
    "deletion": ("EN50159-DELETE-01", "T1-ARQ-02", "T1-ARQ-03"),
    "insertion": ("EN50159-INSERT-01",),
    "resequencing": ("EN50159-RESEQ-01", "T2-DUMP-02"),
    "corruption": ("EN50159-CORRUPT-01", "T1-CRC-01", "T1-CRC-02"),
    "delay": ("EN50159-DELAY-01", "T2-HB-01"),
    "masquerade": ("EN50159-MASQ-01", "T2-ADMIT-01", "T2-ADMIT-02"),
}
"""The requirement ids of the catalogue each threat of the campaign verifies."""

_GREEN, _RED, _YELLOW, _BOLD, _RESET = "\x1b[32m", "\x1b[31m", "\x1b[33m", "\x1b[1m", "\x1b[0m"


class ThreatResultJson(TypedDict):
    """A threat's result as the JSON report gives it (`ThreatResult.as_dict`)."""

    threat: str
    link: str
    injection: str
    defence: str
    caught: bool
    outcome: str
    safe: bool | None
    ran: bool
    verifies: list[str]
    evidence: list[str]


@dataclass
class ThreatResult:
    """`caught`: the named defence reacted on the wire. `safe`: the application outcome was safe;
    None when the devices' state could not be read (a real device) -- the outcome says so."""

    threat: str
    link: str
    injection: str
    defence: str
    caught: bool
    outcome: str
    safe: bool | None
    evidence: list[str] = field(default_factory=list)
    ran: bool = True

    @property
    def verifies(self) -> tuple[str, ...]:
        """The requirement ids this threat's result is evidence for."""
        return REQUIREMENTS.get(self.threat, ())

    @property
    def passed(self) -> bool:
        return not self.ran or (self.caught and self.safe is not False)

    def as_dict(self) -> ThreatResultJson:
        return {"threat": self.threat, "link": self.link, "injection": self.injection,
                "defence": self.defence, "caught": self.caught, "outcome": self.outcome,
                "safe": self.safe, "ran": self.ran, "verifies": list(self.verifies),
                "evidence": self.evidence}  # fmt: skip


def not_run(threat: str, why: str) -> ThreatResult:
    return ThreatResult(threat, "-", "-", "-", False, why, None, ran=False)


def _mark(flag: bool | None) -> str:
    return "yes" if flag else ("not observed" if flag is None else "NO")


def markdown(results: list[ThreatResult]) -> str:
    lines = ["| threat | link | injected through the tap | defence that caught it | caught | "
             "application outcome | safe |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in results:
        caught = _mark(r.caught) if r.ran else "not run"
        lines.append(f"| {r.threat} | {r.link} | {r.injection} | {r.defence} | {caught} | "
                     f"{r.outcome} | {_mark(r.safe) if r.ran else '-'} |")  # fmt: skip
    return "\n".join(lines)


def summary(results: list[ThreatResult], header: list[str], colour: bool) -> str:
    """What a person reads: one block a threat, its verdicts coloured, its evidence indented."""

    def paint(text: str, code: str) -> str:
        return f"{code}{_BOLD}{text}{_RESET}" if colour else text

    out = [*header, ""]
    for r in results:
        if not r.ran:
            out.append(f"{paint('SKIP  ', _YELLOW)} {r.threat:13s} {r.outcome}")
            continue
        verdict = paint("CAUGHT", _GREEN) if r.caught else paint("MISSED", _RED)
        out.append(f"{verdict} {r.threat:13s} {r.link}: {r.injection}")
        out.append(f"       defence: {r.defence}")
        safe = {True: paint("safe", _GREEN), False: paint("UNSAFE", _RED),
                None: paint("not observed", _YELLOW)}[r.safe]  # fmt: skip
        out.append(f"       outcome ({safe}): {r.outcome}")
        out.extend(f"         - {e}" for e in r.evidence)
    ran = [r for r in results if r.ran]
    bad = [r for r in ran if not r.passed]
    head = paint("FAILED", _RED) if bad else paint("PASSED", _GREEN)
    unobserved = sum(1 for r in ran if r.safe is None)
    tail = f"{head}: {sum(r.caught for r in ran)} of {len(ran)} threats caught"
    if unobserved:
        tail += f", {unobserved} application outcomes not observed"
    if len(ran) < len(results):
        tail += f", {len(results) - len(ran)} not run"
    out += ["", tail]
    return "\n".join(out)


def junit_xml(results: list[ThreatResult], properties: dict[str, str]) -> bytes:
    """One <testcase> a threat: a miss or an unsafe outcome is a failure, a threat not run is
    skipped; the evidence goes to system-out."""
    ran = [r for r in results if r.ran]
    root = ET.Element("testsuites", name="ktcs-bench threats")
    ts = ET.SubElement(root, "testsuite", name="ktcs-bench threats EN 50159",
                       tests=str(len(results)), failures=str(sum(not r.passed for r in ran)),
                       errors="0", skipped=str(len(results) - len(ran)))  # fmt: skip
    props = ET.SubElement(ts, "properties")
    for key, value in properties.items():
        ET.SubElement(props, "property", name=key, value=value)
    for r in results:
        tc = ET.SubElement(ts, "testcase", name=r.threat, classname="threats.en50159")
        if r.verifies:
            tprops = ET.SubElement(tc, "properties")
            for rid in r.verifies:
                ET.SubElement(tprops, "property", name=REQUIREMENT, value=rid)
        if not r.ran:
            ET.SubElement(tc, "skipped", message=r.outcome)
            continue
        if not r.passed:
            what = "not caught" if not r.caught else "unsafe outcome"
            ET.SubElement(tc, "failure", message=f"{what}: {r.outcome}",
                          type="ThreatNotDefended").text = f"{r.defence}\n{r.outcome}"  # fmt: skip
        ET.SubElement(tc, "system-out").text = "\n".join(
            [f"link: {r.link}", f"injected: {r.injection}", f"defence: {r.defence}",
             f"outcome: {r.outcome} (safe: {_mark(r.safe)})", *r.evidence]
        )  # fmt: skip
    ET.indent(root)
    out: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    return out
