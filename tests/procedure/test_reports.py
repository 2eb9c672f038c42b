"""What `test run` takes and where it writes (issue 21 items 6, 7, 10, 16): the report paths are
checked before anything runs; a folder of procedures is every procedure file in it, sorted; a
procedure's id never puts a file outside the report folder, nor over another's; and the index
and pages say what the run was -- counts, date, mode, lab, a timeline on a time axis with its
step numbers apart, and no empty speed-distance plot of a train that never moved. Each procedure
runs on its own lab in this process, on the virtual clock."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir

SHIPPED = data_dir("emulators") / "procedures"
QUIET = SHIPPED / "labs" / "quiet.yaml"


def procedure(folder: Path, file: str, ident: str) -> Path:
    """A short procedure on the quiet lab that passes, with id `ident`."""
    path = folder / file
    path.write_text(f"id: {json.dumps(ident)}\ntitle: {file}\nsetup: {{lab: '{QUIET}'}}\n"
                    "steps:\n  - expect: ctc 18 signal 01 is R\n", encoding="utf-8")  # fmt: skip
    return path


# -- item 7: the report paths, checked first -----------------------------------------------------
def bad_paths(tmp: Path) -> list[tuple[list[str], str, str]]:
    (tmp / "a-file").write_text("x", encoding="utf-8")
    return [  # (options, the path named, the problem)
        (["--junit", str(tmp)], str(tmp), "is a folder"),
        (["--junit", "/sys/x.xml"], "/sys/x.xml", "cannot write"),
        (["--junit", str(tmp / "nowhere" / "j.xml")], str(tmp / "nowhere"), "is not there"),
        (["--report", str(tmp / "a-file")], str(tmp / "a-file"), "is a file"),
        (["--report", str(tmp / "a-file" / "out")], str(tmp / "a-file"), "is a file"),
        (["--report", "/sys/report"], "/sys", "cannot write"),
    ]


@pytest.mark.parametrize("case", range(6))
def test_a_report_path_that_cannot_be_written_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: int
) -> None:
    options, path, problem = bad_paths(tmp_path)[case]
    proc = procedure(tmp_path, "p.yaml", "p")
    code = main(["test", "run", str(proc), *options, "--no-colour"])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert out == ""  # nothing ran: no verdict, no report
    assert len(err.splitlines()) == 1 and path in err and problem in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "p.yaml"]


# -- item 10: a folder of procedures ---------------------------------------------------------------
def test_a_folder_means_every_procedure_file_in_it_sorted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "procs"
    (folder / "labs").mkdir(parents=True)
    procedure(folder, "b.yaml", "second")
    procedure(folder, "a.yml", "first")
    procedure(folder / "labs", "c.yaml", "not-in-a-sub-folder")
    (folder / "notes.txt").write_text("not a procedure", encoding="utf-8")
    code = main(["test", "run", str(folder), "--json", "--no-colour"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert [p["id"] for p in json.loads(out)["procedures"]] == ["first", "second"]


def test_a_folder_with_no_procedure_file_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "notes.txt").write_text("not a procedure", encoding="utf-8")
    code = main(["test", "run", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.splitlines() == [f"ktcs-bench: error: test run: no procedure file (*.yaml, *.yml) "
                                f"in the folder {tmp_path}"]  # fmt: skip


# -- item 6: ids are not paths -------------------------------------------------------------------
def test_a_procedure_id_never_writes_outside_the_report_folder_nor_over_another(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    procs, report = tmp_path / "procs", tmp_path / "deep" / "report"
    procs.mkdir()
    ids = [str(tmp_path / "outside"), "../escaped", "a/b", "a_b", "index", "A_B"]
    files = [procedure(procs, f"p{i}.yaml", ident) for i, ident in enumerate(ids)]
    code = main(["test", "run", *map(str, files), "--report", str(report), "--no-colour"])
    assert code == 0, capsys.readouterr()
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert [w for w in written if not w.startswith(("procs/", "deep/report/"))] == []
    pages = sorted(p.name for p in report.glob("*.html"))
    assert len(pages) == len(ids) + 1  # one each, and the index
    links = re.findall(r'<a href="([^"]+)">([^<]+)</a>', (report / "index.html").read_text())
    assert sorted(i for _, i in links) == sorted(ids)
    for page, ident in links:
        assert "/" not in page and not page.startswith(".") and page != "index.html"
        assert f"{ident}: " in (report / page).read_text(encoding="utf-8")  # its own page


# -- item 16: the index and the pages --------------------------------------------------------------
class Elements(HTMLParser):
    """Every element of a page: its tag, its attributes, the text directly in it and the text
    of it with all it holds."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.found: list[tuple[str, dict[str, str], list[str], list[str]]] = []
        self._open: list[int] = []
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for i in self._open:  # an element begins: a word ends
            self.found[i][3].append(" ")
        self.found.append((tag, {k: v or "" for k, v in attrs}, [], []))
        if tag not in ("img", "br", "meta"):
            self._open.append(len(self.found) - 1)

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.found.append((tag, {k: v or "" for k, v in attrs}, [], []))

    def handle_endtag(self, tag: str) -> None:
        while self._open and self.found[self._open.pop()][0] != tag:
            pass

    def handle_data(self, data: str) -> None:
        if self._open:
            self.found[self._open[-1]][2].append(data)
        for i in self._open:
            self.found[i][3].append(data)

    def all(self, tag: str, **attrs: str) -> list[tuple[dict[str, str], str]]:
        """(attributes, the text directly in it) of each element `tag` with `attrs`."""
        return [(a, "".join(own).strip()) for g, a, own, _ in self.found
                if g == tag and all(a.get(k) == v for k, v in attrs.items())]  # fmt: skip

    def text_of(self, tag: str, **attrs: str) -> list[str]:
        return [text for _, text in self.all(tag, **attrs)]

    def whole(self, tag: str, **attrs: str) -> str:
        """All the text of the one element `tag` with `attrs`, a space where another began, its
        spaces made single."""
        (full,) = [f for g, a, _, f in self.found
                   if g == tag and all(a.get(k) == v for k, v in attrs.items())]  # fmt: skip
        return " ".join("".join(full).split())


def test_the_index_and_pages_say_what_the_run_was(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "report"
    names = ("route_set.yaml", "cancel_approach_locked.yaml", "sequential_release.yaml")
    code = main(["test", "run", *(str(SHIPPED / n) for n in names), "--report", str(report),
                 "--no-colour"])  # fmt: skip
    assert code == 0, capsys.readouterr()

    index = Elements((report / "index.html").read_text(encoding="utf-8"))
    assert index.whole("tr", id="summary") == "result 3 passed, 0 failed, 0 in error (of 3)"
    started = index.whole("tr", id="started")
    assert re.fullmatch(r"started \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", started), started
    assert index.whole("tr", id="mode") == "mode virtual"
    assert index.whole("tr", id="lab") == "lab quiet"

    page = Elements((report / "route-set.html").read_text(encoding="utf-8"))
    ticks = [float(t) for t in page.text_of("text", **{"class": "tick"})]
    assert ticks[0] == 0 and ticks == sorted(ticks) and len(ticks) >= 3  # a time axis ...
    assert any("time" in t and "(s" in t for t in page.text_of("text", **{"class": "axis"}))
    labels = page.all("text", **{"class": "step"})
    numbered: set[int] = set()
    for _, text in labels:  # ... and every step that ran, numbered once ("3" or "3-7")
        first, _, last = text.partition("-")
        numbered.update(range(int(first), int(last or first) + 1))
    assert numbered == set(range(1, 15))
    # no two numbers overlap (a digit of an 11 px label is narrower than 6.5 px)
    boxes = [(float(a["x"]), float(a["y"]) - 11, float(a["x"]) + 6.5 * len(t), float(a["y"]))
             for a, t in labels]  # fmt: skip
    for i, (x0, y0, x1, y1) in enumerate(boxes):
        for u0, v0, u1, v1 in boxes[i + 1 :]:
            assert x1 <= u0 or u1 <= x0 or y1 <= v0 or v1 <= y0, (boxes, labels)

    still = Elements((report / "cancel-approach-locked.html").read_text(encoding="utf-8"))
    assert still.all("img", alt="speed-distance") == []  # T1 stood where it was placed
    assert any("T1" in t for t in still.text_of("p", **{"class": "still"}))
    assert len(still.all("img", alt="time-distance")) == 1
    ran = Elements((report / "sequential-release.html").read_text(encoding="utf-8"))
    assert [a["data-trains"] for a, _ in ran.all("img", alt="speed-distance")] == ["T1"]
