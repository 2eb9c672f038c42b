"""What an assessor reads on a procedure's page beyond the verdicts: what produced it (version,
commit, machine), each requirement verified with its sentence, the interlocking's signals beside
the CTC's on the timeline, the faults marked on it, and the procedure and lab files as run."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from ktcs_bench import __version__
from ktcs_bench.datafiles import data_dir
from ktcs_bench.evidence.catalogue import load_catalogue

PROCEDURE = data_dir("emulators") / "procedures" / "type1_comm_error.yaml"


def test_the_page_says_what_made_it_what_it_verifies_and_shows_faults_and_both_views(
    tmp_path: Path,
) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "test", "run",
         str(PROCEDURE), "--report", str(tmp_path / "r")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    page = (tmp_path / "r" / "type1-comm-error.html").read_text(encoding="utf-8")
    index = (tmp_path / "r" / "index.html").read_text(encoding="utf-8")
    for html in (page, index):
        made_by = re.search(r"<td>made by</td><td>([^<]*)</td>", html)
        assert made_by is not None and f"ktcs-bench {__version__}" in made_by[1]
        assert "Python 3." in made_by[1]
    text = load_catalogue().requirements["ATC-CODE-03"].text
    assert "<code>ATC-CODE-03</code> " + text.replace("'", "&#x27;") in page
    assert 'class="fault"' in page  # the link cut, a solid red line on the timeline
    lanes = re.findall(r'<text x="2" y="\d+">([^<]*)</text>', page)
    at = lanes.index("22 signal 01")  # the CTC's lane, then the interlocking's own under it
    assert lanes[at + 1] == "ixl 22 01"
    assert "tags: [fault, type1, atc, resync]" in page  # the procedure file as run
    assert "<summary>its lab, <code>quiet.yaml</code></summary>" in page


def test_a_train_under_atp_is_plotted_with_its_curves_code_and_brakes(tmp_path: Path) -> None:
    procedure = PROCEDURE.with_name("train_hold_dispatch.yaml")
    run = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "test", "run",
         str(procedure), "--report", str(tmp_path / "r")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    page = (tmp_path / "r" / "train-hold-dispatch.html").read_text(encoding="utf-8")
    assert 'data-supervised="T1"' in page  # the train device's EBI/SBI/permitted were sampled


def test_the_devices_logs_show_the_refusals_and_their_reasons(tmp_path: Path) -> None:
    procedure = PROCEDURE.with_name("route_conflict_refused.yaml")
    run = subprocess.run(
        [sys.executable, "-m", "ktcs_bench.cli.main", "--no-colour", "test", "run",
         str(procedure), "--report", str(tmp_path / "r")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    page = (tmp_path / "r" / "route-conflict-refused.html").read_text(encoding="utf-8")
    assert re.search(r'<details class="log" data-device="ixl18">', page)
    assert re.search(r"<b>[^<]*rejected: route conflicts</b>", page)  # the CTC's and the IXL's
    assert re.search(r"<b>[^<]*rejected: point locked</b>", page)
    logs = json.loads((tmp_path / "r" / "results.json").read_text(encoding="utf-8"))
    texts = [e["text"] for e in logs["procedures"][0]["logs"]["ixl18"]]
    assert any("refused" in t or "rejected" in t for t in texts)
