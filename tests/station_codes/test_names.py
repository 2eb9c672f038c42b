"""The station-code layer: every name a station's links carry is spelled once and means one thing
(`parse_code`), and the layer sits under the cores, importing nothing above station data."""

from __future__ import annotations

import pytest

from ktcs_bench.station import Line, load_line
from ktcs_bench.station_codes import names as n
from ktcs_bench.station_codes.names import CodeName, Function
from ktcs_bench.station_codes.stations import (
    LINKS,
    StationCodes,
    link_charts,
    station_chart,
    totalisers,
)
from tests.ctc.test_layers import package_imports, reaches


@pytest.fixture(scope="module")
def line() -> Line:
    return load_line()


def test_every_name_of_every_link_parses_back_to_itself(line: Line) -> None:
    for st in line.stations:
        codes = StationCodes(line.view(st))
        for link, _, _ in LINKS:
            for code in station_chart(line.view(st), link).codes:
                meaning = codes.parse_code(code.name)
                assert meaning is not None, (link, code.name)
                assert meaning.text == code.name
                assert meaning.function == code.type  # the chart's type column


def test_a_name_taken_apart(line: Line) -> None:
    codes = StationCodes(line.view(18))
    assert codes.parse_code("RSC180111") == CodeName(Function.RSC, 18, "0111")
    assert codes.parse_code("SNI1831") == CodeName(Function.SNI, 18, "31")
    # an aspect of two letters is not read as a signal "01Y" showing G
    assert codes.parse_code("ASP1801YG") == CodeName(Function.ASP, 18, "01", "YG")
    assert codes.parse_code("LPS1801G") == CodeName(Function.LPS, 18, "01", "G")
    assert codes.parse_code("TC1853A") == CodeName(Function.TC, 18, "TC1853A")
    assert codes.parse_code("IZC1820") == CodeName(Function.IZC, None, "1820")
    ttc = codes.parse_code("TTC1861A1867")
    assert ttc is not None and ttc.function is Function.TTC and ttc.object == "1820"
    assert ttc.track_circuits == ("TC1861A", "TC1863", "TC1867")
    assert codes.parse_code("CMQ18") == CodeName(Function.CMQ, 18)


def test_a_name_the_station_does_not_have_means_nothing(line: Line) -> None:
    codes = StationCodes(line.view(18))
    for name in ("SNI2031", "RSC189999", "PNC1899", "ASP1801W", "", "TC", "XYZ18"):
        assert codes.parse_code(name) is None, name


def test_the_spelling_functions_and_code_name_agree() -> None:
    assert n.asp(18, "01", "YG") == "ASP1801YG" == str(CodeName(Function.ASP, 18, "01", "YG"))
    assert n.rsc(20, "0112") == "RSC200112"
    assert n.tdu("1820") == "TDU1820" and n.izc("1820") == "IZC1820"
    assert n.cmq(22) == "CMQ22"


def test_totalisers_are_the_station_s_half_of_each_interval(line: Line) -> None:
    view = line.view(18)
    found = {t.interval: t for t in totalisers(view)}
    for iv in view.intervals:
        half = view.owned_half(iv)
        assert (iv.name in found) == bool(half)
        if half:
            assert found[iv.name].track_circuits == half
            assert found[iv.name].name in station_chart(view, "atc_to_ixl")


def test_link_charts_are_the_link_and_its_reverse(line: Line) -> None:
    tx, rx = link_charts(line.view(20), "ixl_to_atc")
    assert (tx.name, rx.name) == ("st20-ixl-to-atc", "st20-atc-to-ixl")
    with pytest.raises(ValueError, match="unknown link"):
        station_chart(line.view(20), "ixl_to_tc")


@pytest.mark.parametrize(
    ("package", "only"),
    [
        ("station_codes", {"station"}),
        ("binding", {"station_codes", "station"}),
    ],
)
def test_the_code_layer_and_the_binding_import_only_what_is_under_them(
    package: str, only: set[str]
) -> None:
    graph = package_imports()
    assert package in graph
    assert reaches(graph, package) <= only | reaches(graph, "station")


def test_station_data_reaches_nothing_built_on_it() -> None:
    above = {"station_codes", "chart_files", "lab", "binding"}
    assert not reaches(package_imports(), "station") & above


@pytest.mark.parametrize("core", ["ixl", "field", "atc"])
def test_the_cores_never_reach_the_chart_files_links_or_processes(core: str) -> None:
    reached = reaches(package_imports(), core)
    assert "station_codes" in reached
    links = {"type1", "type2", "transport", "tap"}
    assert not reached & ({"chart_files", "binding", "emulator"} | links)
