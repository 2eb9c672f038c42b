"""The committed code charts equal what `chart generate` makes, and `chart check` catches errors."""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.cli.main import main
from ktcs_bench.datafiles import data_dir
from ktcs_bench.station import load_line
from ktcs_bench.station_codes.stations import LINKS, build_specs, station_chart, station_links

CHARTS = data_dir("code_charts")


def test_generate_reproduces_the_committed_charts_exactly(tmp_path: Path) -> None:
    assert main(["chart", "generate", "--out", str(tmp_path)]) == 0
    made = sorted(p.name for p in tmp_path.glob("*.yaml"))
    shipped = sorted(p.name for p in CHARTS.glob("st*.yaml"))
    assert made == shipped
    line = load_line()
    links = sum(len(station_links(line.view(st))) for st in line.stations)
    assert len(made) == links == 3 * len(LINKS) + 8  # 18-20 and 20-22: two neighbour links each way
    for name in made:
        assert (tmp_path / name).read_text() == (CHARTS / name).read_text(), name


def test_check_passes_on_the_shipped_charts(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["chart", "check"]) == 0
    assert "ok" in capsys.readouterr().out


def test_paper_mnemonics_and_numbering() -> None:
    chart = load_chart(CHARTS / "st18_ixl_to_ctc.yaml")
    assert chart.protocol == "type2" and chart.direction == "IXL->CTC" and chart.station == 18
    assert [c.name for c in chart.codes[:7]] == [
        "LOC18", "CTC18", "CMR18", "SNI1831", "SRN1831", "SRI1831", "SNR1831",
    ]  # fmt: skip
    assert chart.number_of("LOC18") == 1 and chart.name_of(3) == "CMR18"
    atc = load_chart(CHARTS / "st18_atc_to_ixl.yaml")
    names = [c.name for c in atc.codes]
    assert names[:2] == ["TC1851", "TC1853A"]
    assert {"TC1861A", "TC1863", "TC1867", "IZC1618", "IZC1820", "TTC1861A1867"} <= set(names)
    assert load_chart(CHARTS / "st22_atc_to_ixl.yaml").protocol == "type1"
    ctl = load_chart(CHARTS / "st20_ctc_to_ixl.yaml")
    assert {"CMQ20", "LMQ20", "RSC200111", "RCC200111", "SNC2031", "SRC2031", "SSC2001"} <= {
        c.name for c in ctl.codes
    }


def test_every_chart_fits_the_wire() -> None:
    """Type II code numbers are u16; every name is unique within its chart."""
    for spec in build_specs(load_line()):
        names = [nm for nm, _ in spec.codes]
        assert len(names) == len(set(names)), spec.stem
        assert 0 < len(names) < 0x10000


def _copy(tmp_path: Path) -> Path:
    out = tmp_path / "charts"
    shutil.copytree(CHARTS, out)
    return out


def _check(charts: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(["chart", "check", "--charts", str(charts)])
    return code, capsys.readouterr().err


def _rewrite(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_check_catches_a_duplicate_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    charts = _copy(tmp_path)
    _rewrite(charts / "st20_ixl_to_ctc.yaml", "name: CTC20,", "name: LOC20,")
    code, err = _check(charts, capsys)
    assert code == 1
    assert "st20_ixl_to_ctc.yaml: codes[1].name: duplicate code 'LOC20'" in err


def test_check_catches_an_unknown_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    charts = _copy(tmp_path)
    _rewrite(charts / "st18_atc_to_ixl.yaml", "name: TC1863,", "name: TC1865,")
    code, err = _check(charts, capsys)
    assert code == 1
    assert "unknown code 'TC1865'" in err and "missing code 'TC1863'" in err


def test_check_catches_reordered_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    charts = _copy(tmp_path)
    path = charts / "st22_ixl_to_io.yaml"
    lines = path.read_text().splitlines(keepends=True)
    first = next(i for i, ln in enumerate(lines) if ln.startswith("  - "))
    a, b = lines[first], lines[first + 1]
    lines[first] = b.replace("sequence: 2", "sequence: 1")
    lines[first + 1] = a.replace("sequence: 1", "sequence: 2")
    path.write_text("".join(lines))
    code, err = _check(charts, capsys)
    assert code == 1 and "order differs" in err


def test_check_catches_a_wrong_sequence(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    charts = _copy(tmp_path)
    _rewrite(charts / "st18_ixl_to_atc.yaml", "sequence: 2,", "sequence: 7,")
    code, err = _check(charts, capsys)
    assert code == 1 and "codes[1].sequence: is 7, but the code is number 2" in err


def test_check_catches_missing_and_extra_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    charts = _copy(tmp_path)
    (charts / "st20_io_to_ixl.yaml").rename(charts / "st24_io_to_ixl.yaml")
    code, err = _check(charts, capsys)
    assert code == 1
    assert "st20_io_to_ixl.yaml: missing chart" in err
    assert "st24_io_to_ixl.yaml: unexpected chart" in err


def test_check_catches_disagreement_with_station_data(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Station data gains a point: the charts no longer describe it."""
    emu = tmp_path / "emu"
    shutil.copytree(data_dir("emulators") / "lines", emu / "lines")
    shutil.copytree(data_dir("emulators") / "stations", emu / "stations")
    st18 = emu / "stations" / "st18.yaml"
    text = st18.read_text().replace(
        '  - {name: "32", track_circuits: [TC1857A]',
        '  - {name: "35", track_circuits: [TC1857A], position_m: 1160, facing: down, toe: "1", '
        'normal: "1", reverse: "2"}\n'
        '  - {name: "32", track_circuits: [TC1857A]',
    )
    st18.write_text(text)
    code = main(["chart", "check", "--line", str(emu / "lines" / "reference.yaml")])
    err = capsys.readouterr().err
    assert code == 1 and "missing code 'SNI1835'" in err


def test_station_chart_matches_the_loaded_file() -> None:
    line = load_line()
    for link, _, _ in station_links(line.view(20)):
        built = station_chart(line.view(20), link)
        loaded = load_chart(CHARTS / f"st20_{link}.yaml")
        assert [c.name for c in built.codes] == [c.name for c in loaded.codes]


def test_chart_help_has_an_example(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["chart", "--help"])
    assert "ktcs-bench chart generate" in capsys.readouterr().out


def _drop(path: Path, name: str) -> None:
    """Take code `name` out of a chart file and number the codes after it again."""
    out, k = [], 0
    for ln in path.read_text().splitlines(keepends=True):
        if ln.startswith("  - "):
            if f"name: {name}," in ln:
                continue
            k += 1
            ln = re.sub(r"sequence: \d+", f"sequence: {k}", ln)
        out.append(ln)
    path.write_text("".join(out))


def _swap(path: Path, a: str, b: str) -> None:
    """Swap codes `a` and `b` (their sequence numbers stay where they were)."""
    text = path.read_text()
    text = text.replace(f"name: {a},", "name: @@,").replace(f"name: {b},", f"name: {a},")
    path.write_text(text.replace("name: @@,", f"name: {b},"))


# every code after code 8 is one number off (derived: the chart grows with the data)
_AFTER_8_OF_ST20_IXL_TO_CTC = len(station_chart(load_line().view(20), "ixl_to_ctc")) - 8


@pytest.mark.parametrize(
    ("file", "edit", "wire"),
    [
        (  # renamed: decoders would name code 7 of the ATC's reports after the wrong circuit
            "st18_atc_to_ixl.yaml",
            lambda p: _rewrite(p, "name: TC1863,", "name: TC1865,"),
            "code 7 is 'TC1865' in the file, but the ATC sends and the IXL reads 'TC1863' as code 7",
        ),
        (  # dropped: every code after it is one number off
            "st20_ixl_to_ctc.yaml",
            lambda p: _drop(p, "SLI2031"),
            "code 8 is 'SFI2031' in the file, but the IXL sends and the CTC reads 'SLI2031' as "
            f"code 8 (and {_AFTER_8_OF_ST20_IXL_TO_CTC} more codes differ)",
        ),
        (  # reordered: two route controls swapped
            "st22_ctc_to_ixl.yaml",
            lambda p: _swap(p, "RSC220111", "RCC220111"),
            "code 17 is 'RCC220111' in the file, but the CTC sends and the IXL reads "
            "'RSC220111' as code 17 (and 1 more code differs)",
        ),
    ],
)
def test_check_compares_each_file_with_what_the_emulators_put_on_the_wire(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    file: str,
    edit: Callable[[Path], None],
    wire: str,
) -> None:
    charts = _copy(tmp_path)
    edit(charts / file)
    code, err = _check(charts, capsys)
    assert code == 1
    assert f"{charts / file}: {wire}" in err, err


def test_check_finds_two_neighbours_that_disagree_on_their_interval(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Station 18's ixl_to_east and station 20's west_to_ixl are one link's two ends: a chart
    file changed at one end only is a disagreement chart check names."""
    charts = tmp_path / "charts"
    shutil.copytree(CHARTS, charts)
    _swap(charts / "st20_west_to_ixl.yaml", "PHI1820", "PRQ1820")
    assert main(["chart", "check", "--charts", str(charts)]) == 1
    err = capsys.readouterr().err
    assert "st18_ixl_to_east.yaml: code 1 is 'PHI1820', but" in err
    assert "st20_west_to_ixl.yaml (the other end of interval 1820) reads 'PRQ1820'" in err
