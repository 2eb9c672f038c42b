"""The traceability matrix (SPEC §12): requirement -> checks -> verdicts -> evidence, built from
the catalogue and the results the bench writes -- JUnit of `test run`, `conformance`, `threats`
and pytest (`requirement` testcase properties), and the JSON of `test run --report`,
`conformance --json` and `threats --json` -- with the operation coverage the runs left beside
them (coverage.json) added up. Pure but for reading those files: `read_results` gathers, `trace`
judges, `csv_text` and `html_page` write what a person reads.

A requirement's status: `failed` when any check of it failed or broke (an error is no pass),
`passed` when one passed and none failed, `unchecked` otherwise -- no check names it, or every
check that does was skipped or not applicable, which is not a pass.
"""

from __future__ import annotations

import csv
import html
import io
import json
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypedDict

from ktcs_bench.errors import UsageError
from ktcs_bench.evidence.catalogue import Catalogue
from ktcs_bench.evidence.coverage import is_coverage, merge, never
from ktcs_bench.junit import REQUIREMENT

KINDS = ("procedure", "conformance", "threat", "pytest")
STATUSES = ("failed", "unchecked", "passed")  # the order a person reads them in
_WORST = {"fail": 3, "error": 2, "pass": 1, "skip": 0}


class CheckJson(TypedDict):
    kind: str
    name: str
    verdict: str
    message: str
    evidence: list[str]


class RequirementJson(TypedDict):
    """One catalogue requirement in the matrix: its status and the checks naming it."""

    id: str
    text: str
    source: str
    roles: list[str]
    status: str
    checks: list[CheckJson]


class CoverageCounts(TypedDict):
    requirements: int
    checked: int
    passed: int
    failed: int
    unchecked: int
    checks: int
    checks_naming_no_requirement: int


class TraceJson(TypedDict):
    """`trace.json` (and `trace --json`): the matrix, its counts and what no run exercised."""

    catalogue: str
    generated: str
    results: list[str]
    coverage: CoverageCounts
    requirements: list[RequirementJson]
    operations: dict[str, dict[str, list[str]]]
    operation_coverage: list[str]
    unknown_requirements: dict[str, list[str]]


@dataclass
class Check:
    """One check's verdict: `kind` one of KINDS, `verdict` pass, fail, error or skip."""

    kind: str
    name: str
    verdict: str
    requirements: tuple[str, ...]
    message: str = ""
    evidence: list[str] = field(default_factory=list)

    def add(self, other: Check) -> None:
        """The same check read again (its JUnit and its JSON, or two runs): the worse verdict,
        every piece of evidence."""
        if _WORST[other.verdict] > _WORST[self.verdict]:
            self.verdict, self.message = other.verdict, other.message
        self.requirements = tuple(dict.fromkeys((*self.requirements, *other.requirements)))
        self.evidence += [e for e in other.evidence if e not in self.evidence]

    def as_json(self) -> CheckJson:
        return {"kind": self.kind, "name": self.name, "verdict": self.verdict,
                "message": self.message,  # the report pages first: they hold the rest
                "evidence": sorted(self.evidence, key=lambda e: not e.endswith(".html"))}  # fmt: skip


@dataclass
class Results:
    checks: dict[tuple[str, str], Check] = field(default_factory=dict)
    coverage: dict[Path, dict[str, Any]] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)
    unlinked: int = 0  # checks that name no requirement

    def add(self, check: Check) -> None:
        if not check.requirements:
            self.unlinked += 1
            return
        key = (check.kind, check.name)
        if key in self.checks:
            self.checks[key].add(check)
        else:
            self.checks[key] = check


# -- reading --------------------------------------------------------------------------------------
def _files(words: Sequence[str]) -> list[tuple[Path, bool]]:
    """(file, named by the user) for each argument; a folder stands for every *.xml and *.json
    under it."""
    out: list[tuple[Path, bool]] = []
    for word in words:
        path = Path(word)
        if path.is_dir():
            out += [(p, False) for p in sorted(path.rglob("*"))
                    if p.suffix in (".xml", ".json") and p.is_file()]  # fmt: skip
        elif path.is_file():
            out.append((path, True))
        else:
            raise UsageError(f"trace: {word}: no such file or folder")
    return out


def read_results(words: Sequence[str]) -> Results:
    """Every check and every coverage document the files (and folders) hold. A file named on the
    command line that is no result of the bench is refused; one found in a folder is passed
    over."""
    res = Results()
    for path, named in _files(words):
        try:
            found = _read(path, res)
        except (ET.ParseError, ValueError, UnicodeDecodeError) as exc:
            if named:
                raise UsageError(f"trace: {path}: not readable as JUnit XML or JSON ({exc})") \
                    from None  # fmt: skip
            found = False
        except OSError as exc:
            raise UsageError(f"trace: {path}: {exc.strerror or exc}") from None
        if found:
            res.files.append(path)
        elif named:
            raise UsageError(f"trace: {path}: not a result the bench writes (JUnit of test run, "
                             "conformance, threats or pytest; their JSON; coverage.json)")  # fmt: skip
    return res


def _coverage_beside(path: Path, name: str, res: Results) -> None:
    beside = path.parent / name
    if beside.is_file() and beside.resolve() not in res.coverage:
        try:
            doc = json.loads(beside.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            return
        if is_coverage(doc):
            res.coverage[beside.resolve()] = doc


def _read(path: Path, res: Results) -> bool:
    if path.suffix == ".xml":
        return _read_junit(path, res)
    doc = json.loads(path.read_text(encoding="utf-8"))
    if is_coverage(doc):
        res.coverage.setdefault(path.resolve(), doc)
        return True
    if not isinstance(doc, dict):
        return False
    if isinstance(doc.get("procedures"), list):
        _read_procedures_json(path, doc, res)
    elif isinstance(doc.get("cases"), list) and "role" in doc:
        for c in doc["cases"]:
            frames = len(c.get("frames", []))
            ev = [str(path)] + ([f"{frames} frames captured ({path.name})"] if frames else [])
            res.add(Check("conformance", f"{doc['role']}:{c['name']}", _verdict(c["verdict"]),
                          tuple(c.get("verifies", ())), c.get("message", ""), ev))  # fmt: skip
    elif isinstance(doc.get("results"), list) and "targets" in doc:
        for t in doc["results"]:
            verdict = ("skip" if not t.get("ran") else
                       "pass" if t.get("caught") and t.get("safe") is not False else "fail")  # fmt: skip
            res.add(Check("threat", str(t["threat"]), verdict, tuple(t.get("verifies", ())),
                          str(t.get("outcome", "")), [str(path), *t.get("evidence", [])[:3]]))  # fmt: skip
    else:
        return False
    return True


def _verdict(word: str) -> str:
    return {"pass": "pass", "passed": "pass", "fail": "fail", "failed": "fail",
            "error": "error", "skip": "skip", "skipped": "skip",
            "not applicable": "skip"}.get(word, "error")  # fmt: skip


def _read_procedures_json(path: Path, doc: dict[str, Any], res: Results) -> None:
    for p in doc["procedures"]:
        ev = [str(path)]
        page = str(p.get("page") or "")
        if page and (path.parent / page).is_file():
            ev.insert(0, str(path.parent / page))  # the page: steps, timeline, captures
        if p.get("file"):
            ev.append(str(p["file"]))
        res.add(Check("procedure", str(p["id"]), _verdict(str(p.get("verdict"))),
                      tuple(p.get("verifies", ())), str(p.get("message", "")), ev))  # fmt: skip
    if isinstance(doc.get("coverage"), str):
        _coverage_beside(path, doc["coverage"], res)


def _kind(classname: str) -> str:
    head = classname.split(".", 1)[0]
    return {"procedure": "procedure", "conformance": "conformance", "threats": "threat"}.get(
        head, "pytest"
    )


def _read_junit(path: Path, res: Results) -> bool:
    root = ET.parse(path).getroot()
    if root.tag not in ("testsuites", "testsuite"):
        return False
    for suite in [root] if root.tag == "testsuite" else root.iter("testsuite"):
        props = {p.get("name"): p.get("value") for p in suite.findall("properties/property")}
        if props.get("coverage"):
            _coverage_beside(path, str(props["coverage"]), res)
        for tc in suite.iter("testcase"):
            classname, name = tc.get("classname", ""), tc.get("name", "")
            kind = _kind(classname)
            own = [(p.get("name"), p.get("value") or "") for p in tc.findall("properties/property")]
            ids = tuple(v for k, v in own if k == REQUIREMENT)
            verdict, message = "pass", ""
            for tag, word in (("failure", "fail"), ("error", "error"), ("skipped", "skip")):
                el = tc.find(tag)
                if el is not None:
                    verdict, message = word, el.get("message", "")
                    break
            ev = [str(path)] + [v for k, v in own if k == "file"]
            if kind == "procedure":
                check_name = name
            elif kind == "conformance":
                check_name = f"{classname.rsplit('.', 1)[-1]}:{name}"
                ev.append(f"checks and frames: system-out of {name} ({path.name})")
            elif kind == "threat":
                check_name = name
                ev.append(f"evidence: system-out of {name} ({path.name})")
            else:
                check_name = f"{classname}::{name}"
            res.add(Check(kind, check_name, verdict, ids, message, ev))
    return True


# -- judging --------------------------------------------------------------------------------------
def trace(catalogue: Catalogue, res: Results) -> TraceJson:
    """The matrix: every requirement of the catalogue with its status and checks, the counts,
    what no run exercised, and the ids the results name that the catalogue lacks."""
    by_id: dict[str, list[Check]] = {}
    unknown: dict[str, list[str]] = {}
    for check in res.checks.values():
        for rid in check.requirements:
            if rid in catalogue:
                by_id.setdefault(rid, []).append(check)
            else:
                unknown.setdefault(rid, []).append(f"{check.kind} {check.name}")
    reqs: list[RequirementJson] = []
    for r in catalogue.requirements.values():
        checks = sorted(by_id.get(r.id, []), key=lambda c: (KINDS.index(c.kind), c.name))
        verdicts = {c.verdict for c in checks}
        status = ("failed" if verdicts & {"fail", "error"} else
                  "passed" if "pass" in verdicts else "unchecked")  # fmt: skip
        reqs.append({"id": r.id, "text": r.text, "source": r.source, "roles": list(r.roles),
                     "status": status, "checks": [c.as_json() for c in checks]})  # fmt: skip
    count = {s: sum(1 for r in reqs if r["status"] == s) for s in STATUSES}
    coverage = merge(res.coverage.values()) if res.coverage else None
    return {
        "catalogue": str(catalogue.path),
        "generated": datetime.now(UTC).isoformat(timespec="seconds"),
        "results": [str(p) for p in res.files],
        "coverage": {
            "requirements": len(reqs),
            "checked": len(reqs) - count["unchecked"],
            "passed": count["passed"],
            "failed": count["failed"],
            "unchecked": count["unchecked"],
            "checks": len(res.checks),
            "checks_naming_no_requirement": res.unlinked,
        },  # fmt: skip
        "requirements": reqs,
        "operations": never(coverage) if coverage is not None else {},
        "operation_coverage": [str(p) for p in res.coverage],
        "unknown_requirements": unknown,
    }


def failing(doc: TraceJson) -> list[str]:
    return [r["id"] for r in doc["requirements"] if r["status"] == "failed"]


def _reading_order(doc: TraceJson) -> list[RequirementJson]:
    """Failing first, then unchecked, then passed; the catalogue's order within each."""
    return sorted(doc["requirements"], key=lambda r: STATUSES.index(r["status"]))


# -- writing ---------------------------------------------------------------------------------------
def csv_text(doc: TraceJson) -> str:
    """One row per requirement and check (a requirement nothing checks: one row, no check)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["id", "status", "text", "source", "check_kind", "check", "verdict", "evidence"])
    for r in _reading_order(doc):
        head = [r["id"], r["status"], r["text"], r["source"]]
        if not r["checks"]:
            w.writerow(head + ["", "", "", ""])
        for c in r["checks"]:
            w.writerow(head + [c["kind"], c["name"], c["verdict"], "; ".join(c["evidence"])])
    return out.getvalue()


CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:1.5em;color:#222}h1{font-size:1.4em}
h2{font-size:1.15em;margin-top:1.6em}table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ccc;padding:3px 7px;text-align:left;vertical-align:top}th{background:#f2f2f2}
.passed,.pass{color:#fff;background:#2a8a3a}.failed,.fail{color:#fff;background:#c0392b}
.error{color:#fff;background:#8e44ad}.unchecked,.skip{color:#333;background:#f0d060}
.v{font-weight:bold;padding:1px 6px;border-radius:3px;white-space:nowrap}
ul{margin:0;padding-left:1.2em}table.m{width:100%;table-layout:fixed}
table.m th:nth-child(1){width:10em}table.m th:nth-child(2){width:6.5em}table.m th:nth-child(3){width:38%}
table.m td{overflow-wrap:anywhere}.src{color:#666;font-size:.9em}code{background:#f5f5f5}
"""


def _e(text: object) -> str:
    return html.escape(str(text))


def _evidence(item: str, out: Path) -> str:
    path = Path(item)
    if path.suffix and path.is_file():
        rel = os.path.relpath(path.resolve(), out.resolve())
        return f'<a href="{_e(rel)}">{_e(path.name)}</a>'
    return _e(item)


def html_page(doc: TraceJson, out: Path) -> str:
    """A self-contained page (no script, no file beside it but the evidence it links to)."""
    cov = doc["coverage"]
    rows = []
    for r in _reading_order(doc):
        checks = "".join(
            f'<li><span class="v {_e(c["verdict"])}">{_e(c["verdict"])}</span> {_e(c["kind"])} '
            f"<code>{_e(c['name'])}</code>"
            + (
                f" -- {_e(c['message'])}" if c["message"] and c["verdict"] != "pass" else ""
            )  # fmt: skip
            + f'<br><span class="src">{" · ".join(_evidence(e, out) for e in c["evidence"])}'
            "</span></li>"
            for c in r["checks"]
        )
        rows.append(
            f'<tr><td><code>{_e(r["id"])}</code></td><td><span class="v {r["status"]}">'
            f'{r["status"]}</span></td><td>{_e(r["text"])}<br><span class="src">'
            f"{_e(r['source'])}</span></td><td>{f'<ul>{checks}</ul>' if checks else '-'}</td></tr>"
        )
    ops = []
    for finding, stations in doc["operations"].items():
        cells = "".join(f"<tr><td>{_e(st)}</td><td>{_e(', '.join(items) or '-')}</td></tr>"
                        for st, items in stations.items())  # fmt: skip
        ops.append(f"<h3>{_e(finding.replace('_', ' '))}</h3><table><tr><th>station</th>"
                   f"<th>never</th></tr>{cells}</table>")  # fmt: skip
    unknown = "".join(f"<li><code>{_e(k)}</code>: {_e('; '.join(v))}</li>"
                      for k, v in doc["unknown_requirements"].items())  # fmt: skip
    pct = 100 * cov["checked"] / cov["requirements"] if cov["requirements"] else 0.0
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>ktcs-bench traceability</title>
<style>{CSS}</style></head><body>
<h1>Traceability: requirements, checks, verdicts, evidence</h1>
<p>Catalogue <code>{_e(doc["catalogue"])}</code>, {_e(doc["generated"])}; results read:
{_e(", ".join(doc["results"]) or "none")}.</p>
<table><tr><th>requirements</th><th>checked</th><th>passed</th><th>failed</th><th>unchecked</th>
<th>checks</th></tr><tr><td>{cov["requirements"]}</td><td>{cov["checked"]} ({pct:.0f} %)</td>
<td>{cov["passed"]}</td><td>{cov["failed"]}</td><td>{cov["unchecked"]}</td>
<td>{cov["checks"]}</td></tr></table>
{f"<h2>Ids the results name that the catalogue lacks</h2><ul>{unknown}</ul>" if unknown else ""}
<h2>Requirements (failing, then unchecked, then passed)</h2>
<table class="m"><tr><th>id</th><th>status</th><th>requirement and source</th><th>checks</th></tr>
{"".join(rows)}</table>
<h2>Operation coverage: what no run exercised</h2>
{"".join(ops) or "<p>No run left its operation coverage (coverage.json) beside its results.</p>"}
</body></html>
"""


def write_trace(doc: TraceJson, out: Path) -> list[Path]:
    """OUT/trace.json, OUT/trace.csv and OUT/index.html."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "trace.json", out / "trace.csv", out / "index.html"]
    paths[0].write_text(json.dumps(doc, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    paths[1].write_text(csv_text(doc), encoding="utf-8")
    paths[2].write_text(html_page(doc, out), encoding="utf-8")
    return paths


def summary_lines(doc: TraceJson) -> Iterable[str]:
    cov = doc["coverage"]
    yield (f"{cov['requirements']} requirements: {cov['passed']} passed, {cov['failed']} failed, "
           f"{cov['unchecked']} unchecked ({cov['checks']} checks read)")  # fmt: skip
    for r in _reading_order(doc):
        if r["status"] == "failed":
            bad = [c["name"] for c in r["checks"] if c["verdict"] in ("fail", "error")]
            yield f"  FAILED    {r['id']}: {', '.join(bad)}"
    unchecked = [r["id"] for r in doc["requirements"] if r["status"] == "unchecked"]
    if unchecked:
        yield f"  unchecked: {', '.join(unchecked)}"
    for rid, checks in doc["unknown_requirements"].items():
        yield f"  not in the catalogue: {rid} (named by {', '.join(checks)})"
    never_set = doc["operations"].get("routes_never_set", {})
    if never_set:
        yield "  routes never set: " + "; ".join(f"{st}: {' '.join(v) or '-'}"
                                                 for st, v in never_set.items())  # fmt: skip
