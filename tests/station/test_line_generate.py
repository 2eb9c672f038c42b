"""`line generate`: an N-station line on the reference stations' patterns that every existing check
accepts (station/line loader, lab loader, code charts), the same bytes for the same N, and
routes whose geometry and interlocking tables hold together."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ktcs_bench.chart_files.check import check_charts
from ktcs_bench.cli.main import main
from ktcs_bench.lab.generate import write_line
from ktcs_bench.lab.topology import load_lab
from ktcs_bench.station import Line, Route, Station, load_line
from ktcs_bench.station.generate import (
    MAX_STATIONS,
    PATTERNS,
    line_files,
    station_numbers,
)

SIZES = (1, 3, 10, 20)
REFERENCE = load_line()  # the shipped line, whose stations are the patterns


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("n", SIZES)
def test_generated_line_loads_and_its_lab_names_every_station(n: int, tmp_path: Path) -> None:
    write_line(n, tmp_path)
    line = load_line(tmp_path / "line.yaml")
    numbers = sorted(line.stations)
    assert len(numbers) == n
    assert all(10 <= s <= 99 for s in numbers)  # two-digit station numbers, as the mnemonics use
    lab = load_lab(tmp_path / "lab.yaml")
    assert lab.line_file == (tmp_path / "line.yaml").resolve()
    assert lab.stations == numbers
    for s in numbers:
        kinds = {d.kind for d in lab.devices.values() if d.station == s}
        assert kinds == {"ixl", "atc", "trackside"}
        station_links = [lk for lk in lab.links if lk.a == f"ixl{s}" and lk.interval is None]
        assert {(lk.type, lab.devices[lk.b].kind) for lk in station_links} == {
            ("type2", "ctc"), ("type1", "atc"), ("type1", "trackside"),
        }  # fmt: skip
        assert all(lk.tap for lk in lab.links)
    # adjacent stations' IXLs: one Type I link per interval, west end first (SPEC §6.6)
    between = [(lk.name, lk.type, lk.a, lk.b, lk.roles) for lk in lab.links if lk.interval]
    assert between == [
        (f"iv{w}{e}", "type1", f"ixl{w}", f"ixl{e}", ("east", "west"))
        for w, e in zip(numbers, numbers[1:], strict=False)
    ]
    assert [d.kind for d in lab.devices.values()].count("ctc") == 1
    assert [d.kind for d in lab.devices.values()].count("trackcircuit") == 1
    # the timetable's trains run in it: the lab names the timetable, a train device runs each
    # of its trains, and the CTC's ARS sets their routes at every station
    assert lab.timetable_file == (tmp_path / "timetable.yaml").resolve()
    timetable = lab.load_timetable()
    assert timetable is not None
    trains = {d.options["train"] for d in lab.devices.values() if d.kind == "train"}
    assert trains == {t.id for t in timetable.trains} == {"T1", "T2"}
    assert lab.ars is not None and lab.ars.start_on == tuple(numbers)


@pytest.mark.parametrize("n", SIZES)
def test_same_n_gives_the_same_bytes_wherever_written(n: int, tmp_path: Path) -> None:
    write_line(n, tmp_path / "a")
    write_line(n, tmp_path / "elsewhere" / "b")
    a, b = _files(tmp_path / "a"), _files(tmp_path / "elsewhere" / "b")
    assert a == b
    # each station's six charts, and two each way between each pair of neighbouring IXLs
    assert len([f for f in a if f.startswith("code_charts/")]) == 6 * n + 4 * (n - 1)
    assert str(tmp_path) not in "".join(t.decode() for t in a.values())  # relative paths only


def test_a_different_n_gives_a_different_line() -> None:
    assert line_files(3)["line.yaml"] != line_files(4)["line.yaml"]


@pytest.mark.parametrize("n", SIZES)
def test_chart_check_passes_on_the_generated_charts(n: int, tmp_path: Path) -> None:
    write_line(n, tmp_path)
    assert check_charts(load_line(tmp_path / "line.yaml"), tmp_path / "code_charts") == []


def test_chart_check_command_passes_and_fails_on_an_edited_chart(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["line", "generate", "--stations", "3", "--out", str(tmp_path)]) == 0
    args = ["chart", "check", "--charts", str(tmp_path / "code_charts"),
            "--line", str(tmp_path / "line.yaml")]  # fmt: skip
    assert main(args) == 0
    chart = tmp_path / "code_charts" / "st14_ixl_to_ctc.yaml"
    chart.write_text(chart.read_text().replace("TC1455", "TC1499"))
    assert main(args) == 1
    assert "TC1499" in capsys.readouterr().err


def _covered_along(tcs: list[tuple[float, float]], lo: float, hi: float) -> bool:
    """The spans (from, to) cover [lo, hi] end to end, without a gap or an overlap."""
    at = lo
    for a, b in sorted(tcs):
        if a != at:
            return False
        at = b
    return at == hi


def _check_route_geometry(st: Station, r: Route) -> None:
    tcs = [st.track_circuit(t) for t in r.track_circuits]
    entry, exit_ = st.signal(r.entry), st.signal(r.exit)
    up = r.direction == "up"
    # a route runs from its entry signal to its exit signal through adjacent track circuits
    assert (tcs[0].from_m if up else tcs[0].to_m) == entry.position_m, r.name
    assert (tcs[-1].to_m if up else tcs[-1].from_m) == exit_.position_m, r.name
    for a, b in zip(tcs, tcs[1:], strict=False):
        assert (a.to_m == b.from_m) if up else (a.from_m == b.to_m), r.name
    own = {x.name for x in st.track_circuits}
    assert set(r.overlap_track_circuits) <= own, r.name  # the overlap lies in the station
    if r.overlap_track_circuits:  # ... and starts at the exit
        first = st.track_circuit(r.overlap_track_circuits[0])
        assert (first.from_m if up else first.to_m) == exit_.position_m, r.name
    for s in r.all_points:  # the points it sets lie in its track circuits or overlap
        assert set(st.point(s.point).track_circuits) & set(r.all_track_circuits), (r.name, s)


def _check_station(line: Line, st: Station) -> None:
    view = line.view(st.number)
    handled = {t.name for t in view.track_circuits}
    for r in st.routes:
        for c in r.conflicts:  # conflicts are mutual
            assert r.name in st.route(c).conflicts, (st.number, r.name, c)
        assert set(r.approach) <= handled, (st.number, r.name)
        _check_route_geometry(st, r)
    # every signal has the routes the pattern gives it: a home signal one to every starting
    # signal of its direction, approached from the plain-line track circuit in front of it; a
    # starting signal exactly one, out to the block limit of its direction; a shunt signal one
    for sig in st.signals:
        mine = [r for r in st.routes if r.entry == sig.name]
        exits = {st.signal(r.exit).kind for r in mine}
        if sig.kind == "home":
            starting = {s.name for s in st.signals
                        if s.kind == "starting" and s.direction == sig.direction}  # fmt: skip
            assert {r.exit for r in mine} == starting, (st.number, sig.name)
            plain = {t.name: t for t in line.track_circuits if t.station == st.number}
            for r in mine:
                (approach,) = r.approach
                ends = plain[approach].to_m if sig.direction == "up" else plain[approach].from_m
                assert ends == sig.position_m, (st.number, r.name, approach)
        elif sig.kind == "starting":
            assert len(mine) == 1 and exits == {"marker"}, (st.number, sig.name)
            assert view.interval_of_exit(mine[0]) is not None, (st.number, sig.name)
        elif sig.kind == "shunt":
            assert len(mine) == 1, (st.number, sig.name)
        else:
            assert mine == [], (st.number, sig.name)
    # the station has what its pattern has: tracks, points, signals and route names
    pattern = REFERENCE.station(PATTERNS[station_numbers(len(line.stations)).index(st.number) % 3])
    assert st.tracks == pattern.tracks
    assert [p.name for p in st.points] == [p.name for p in pattern.points]
    assert [(s.name, s.kind) for s in st.signals] == [(s.name, s.kind) for s in pattern.signals]
    assert [r.name for r in st.routes] == [r.name for r in pattern.routes]


@settings(max_examples=6, deadline=None)
@given(n=st.integers(1, MAX_STATIONS))
@example(n=1)
@example(n=2)
@example(n=MAX_STATIONS)
def test_generated_routes_are_consistent(n: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for rel, text in line_files(n, REFERENCE).items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_text(text)
        line = load_line(folder / "line.yaml")
        for st_ in line.stations.values():
            _check_station(line, st_)
        # the main track runs end to end, one track circuit after the other
        main_track = [(t.from_m, t.to_m) for t in line.all_track_circuits() if t.on_track("1")]
        assert _covered_along(main_track, line.start_m, line.end_m)
        for iv in line.intervals:  # an interval's track circuits fill it, in up order
            spans = [(line_tc.from_m, line_tc.to_m) for t in iv.track_circuits
                     for line_tc in line.track_circuits if line_tc.name == t]  # fmt: skip
            assert spans == sorted(spans) and _covered_along(spans, iv.from_m, iv.to_m), iv.name
        names = [iv.name for iv in line.intervals]
        numbers = sorted(line.stations)
        assert names[0] == f"{numbers[0] - 2}{numbers[0]}" and len(names) == n + 1
        for lo, hi in ((g.from_m, g.to_m) for g in line.gradients):
            assert line.start_m <= lo < hi <= line.end_m
        assert _covered_along([(g.from_m, g.to_m) for g in line.gradients], 0, line.end_m)
        assert _covered_along([(s.from_m, s.to_m) for s in line.speed_limits], 0, line.end_m)


@pytest.mark.parametrize("n", SIZES)
def test_timetable_runs_two_trains_end_to_end_with_platform_stops(n: int) -> None:
    files = line_files(n)
    doc = yaml.safe_load(files["timetable.yaml"])
    assert doc["line"] == "line.yaml"
    data = doc["train_data"][doc["trains"][0]["train"]]
    assert data["length_m"] == 200 and data["max_speed_kmh"] == 80  # seed 001 Table 1
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in files.items():
            (Path(tmp) / rel).parent.mkdir(parents=True, exist_ok=True)
            (Path(tmp) / rel).write_text(text)
        line = load_line(Path(tmp) / "line.yaml")
    trains = doc["trains"]
    assert [t["id"] for t in trains] == ["T1", "T2"]
    assert trains[1]["depart_s"] > trains[0]["depart_s"]  # the second follows the first
    for t in trains:
        assert t["train"] in doc["train_data"] and t["direction"] == "up"
        stops = t["stops"]
        assert [s["station"] for s in stops] == sorted(line.stations)
        assert [s["stop_m"] for s in stops] == sorted(s["stop_m"] for s in stops)
        for s in stops:
            station = line.station(s["station"])
            assert s["track"] in station.tracks and s["dwell_s"] >= 0
            # the whole train stands on its platform track, clear of the points
            platform = [c for c in station.track_circuits if c.tracks == (s["track"],)]
            assert any(c.from_m + data["length_m"] <= s["stop_m"] <= c.to_m for c in platform), s


def _exit_code(argv: list[str]) -> int:
    """The exit status of `ktcs-bench ARGV`: main's return, or argparse's exit."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def test_bad_station_counts_and_a_non_empty_folder_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for n in ("0", str(MAX_STATIONS + 1), "three"):
        assert _exit_code(["line", "generate", "--stations", n, "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()
    (tmp_path / "mine.txt").write_text("keep")
    assert main(["line", "generate", "--stations", "2", "--out", str(tmp_path)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert main(["line", "generate", "--stations", "2", "--out", str(tmp_path), "--force"]) == 0
    assert main(["line", "generate", "--stations", "1", "--out", str(tmp_path), "--force"]) == 0
    assert (tmp_path / "mine.txt").read_text() == "keep"  # --force replaces only a generated line
    assert sorted(p.name for p in (tmp_path / "stations").iterdir()) == ["st12.yaml"]
    assert main(["chart", "check", "--charts", str(tmp_path / "code_charts"),
                 "--line", str(tmp_path / "line.yaml")]) == 0  # fmt: skip
