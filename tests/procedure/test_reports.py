"""What `test run` takes and where it writes (issue 21 items 6, 7, 10): the report paths are
checked before anything runs; a folder of procedures is every procedure file in it, sorted; and a
procedure's id never puts a file outside the report folder, nor over another's. Each procedure
runs on its own lab in this process, on the virtual clock."""

from __future__ import annotations

import json
import re
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
