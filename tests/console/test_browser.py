"""The console in headless Chromium against a running bench (real CTC, IXLs, tap, TCP sockets).

Each test waits for conditions on the page (Playwright's auto-waiting, 10 s default), never for a
fixed time. Station 18 runs through a TCP tap, 20 directly, 22 starts in local mode.
"""

from __future__ import annotations

import re
from typing import Any

from playwright.sync_api import expect

from ktcs_bench.ixl.modes import Mode
from ktcs_bench.train.endpoint import CycleInputs
from tests.console.conftest import ARTIFACTS, Bench


def tc(page: Any, name: str) -> Any:
    return page.locator(f'#diagram line.tc[data-tc="{name}"]').first


def signal(page: Any, station: int, name: str) -> Any:
    return page.locator(f"#sig-{station}-{name}")


def click(page: Any, station: int, name: str) -> None:
    signal(page, station, name).click()


def test_page_draws_the_line_and_each_stations_mode_and_link(page: Any, bench: Bench) -> None:
    for st in bench.line.stations.values():
        for t in st.track_circuits:
            expect(tc(page, t.name)).to_have_count(1)
        for s in st.signals:
            expect(signal(page, st.number, s.name)).to_have_count(1)
        for p in st.points:
            expect(page.locator(f"#pt-{st.number}-{p.name}")).to_have_attribute(
                "data-position", "normal"
            )
    for t in bench.line.track_circuits:
        expect(tc(page, t.name)).to_have_count(1)
    expect(page.locator("#card-18 .mode")).to_have_text("center")
    expect(page.locator("#card-22 .mode")).to_have_text("local")
    for n in (18, 20, 22):
        expect(page.locator(f"#card-{n} .link")).to_have_text("link up")
        expect(page.locator(f"#st-{n}")).to_have_attribute("data-link", "up")
    expect(signal(page, 18, "01")).to_have_attribute("data-aspect", "R")
    expect(tc(page, "TC1855")).not_to_have_class(re.compile(r"\b(locked|occupied|unknown)\b"))


def test_route_set_by_clicks_locks_the_route_and_clears_the_signal(page: Any, bench: Bench) -> None:
    click(page, 18, "01")
    expect(signal(page, 18, "01")).to_have_class(re.compile(r"\bselected\b"))
    click(page, 18, "11")
    expect(page.locator("#result")).to_have_text("station 18: set route 01-11: accepted")
    for name in ("TC1853A", "TC1855", "TC1857A"):  # route and overlap
        expect(tc(page, name)).to_have_class(re.compile(r"\blocked\b"))
    expect(tc(page, "TC1856")).not_to_have_class(re.compile(r"\blocked\b"))
    expect(signal(page, 18, "01")).to_have_attribute("data-aspect", re.compile(r"^(Y|YG|G)$"))
    expect(page.locator("#pt-18-31")).to_have_class(re.compile(r"\blocked\b"))
    # the route runs straight over point 31: its diverging leg is not drawn as part of it
    leg = page.locator('#diagram .tc[data-station="18"][data-point="31"][data-leg="reverse"]')
    expect(leg).to_have_class(re.compile(r"\binactive\b"))
    expect(page.locator("#log .entry.ok").first).to_contain_text("set route 01-11: accepted")
    # the CTC really holds it (the page is not just echoing the click)
    rig = bench.rigs[18]
    assert bench.do(lambda: rig.rig.ctc["RSI180111"]) == 1
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "route_set.png"
    page.screenshot(path=str(shot), full_page=True)
    print(f"\nconsole screenshot: {shot}")

    # a conflicting route is refused by the IXL, with the reason named in type2.yaml
    click(page, 18, "01")
    click(page, 18, "12")
    expect(page.locator("#result")).to_have_text(
        "station 18: set route 01-12: rejected: route conflicts"
    )
    expect(page.locator("#result")).to_have_class("error")
    expect(tc(page, "TC1856")).not_to_have_class(re.compile(r"\blocked\b"))

    # cancel it again: the route releases and the signal returns to stop
    page.click('#tools button[data-tool="cancel"]')
    click(page, 18, "01")
    expect(page.locator("#result")).to_have_text("station 18: cancel route 01-11: accepted")
    for name in ("TC1853A", "TC1855", "TC1857A"):
        expect(tc(page, name)).not_to_have_class(re.compile(r"\blocked\b"))
    expect(signal(page, 18, "01")).to_have_attribute("data-aspect", "R")


def test_no_route_between_the_clicked_signals_is_refused_by_the_console(page: Any) -> None:
    click(page, 18, "01")
    click(page, 18, "02")
    expect(page.locator("#result")).to_have_text("station 18: no route from signal 01 to 02")
    expect(page.locator("#result")).to_have_class("error")
    expect(page.locator("#log .entry.error").first).to_contain_text("no route from signal 01 to 02")


def test_point_moves_reverse_and_back_showing_the_moving_state(page: Any, bench: Bench) -> None:
    point = page.locator("#pt-20-33")
    page.click('#tools button[data-tool="reverse"]')
    point.locator(".pt-dot").click()
    expect(page.locator("#result")).to_have_text("station 20: point 33 to reverse: accepted")
    expect(point).to_have_attribute("data-position", "to_reverse")  # throw takes 2 s
    expect(point).to_have_class(re.compile(r"\bmoving\b"))
    expect(point).to_have_attribute("data-position", "reverse")
    legs = '#diagram .tc[data-station="20"][data-point="33"]'
    expect(page.locator(f'{legs}[data-leg="reverse"]')).not_to_have_class(re.compile("inactive"))
    expect(page.locator(f'{legs}[data-leg="normal"]')).to_have_class(re.compile(r"\binactive\b"))
    page.click('#tools button[data-tool="normal"]')
    point.locator(".pt-dot").click()
    expect(point).to_have_attribute("data-position", "normal")


def test_station_in_local_mode_refuses_then_center_request_and_grant(
    page: Any, bench: Bench
) -> None:
    click(page, 22, "01")
    click(page, 22, "11")
    expect(page.locator("#result")).to_have_text(
        "station 22: set route 01-11: rejected: not in center mode"
    )
    page.click('#card-22 button[data-mode="center"]')
    expect(page.locator("#result")).to_have_text("station 22: request center mode: accepted")
    expect(page.locator("#card-22 .mode")).to_have_text("requested")
    bench.do(lambda: bench.rigs[22].local("grant"))  # the local operator grants it
    expect(page.locator("#card-22 .mode")).to_have_text("center")
    expect(page.locator("#st-22")).to_have_attribute("data-mode", "center")
    page.click('#card-22 button[data-mode="local"]')
    expect(page.locator("#card-22 .mode")).to_have_text("local")


def test_occupancy_and_link_loss_are_shown(page: Any, bench: Bench) -> None:
    bench.do(lambda: bench.rigs[18].occupy("TC1863"))
    expect(tc(page, "TC1863")).to_have_class(re.compile(r"\boccupied\b"))
    bench.do(lambda: bench.rigs[18].occupy("TC1863", False))
    expect(tc(page, "TC1863")).not_to_have_class(re.compile(r"\boccupied\b"))
    # station 20's IXL goes away: link down, its picture no longer trusted; then it comes back
    bench.call(bench.rigs[20].close())
    expect(page.locator("#card-20 .link")).to_have_text("link down")
    expect(tc(page, "TC2055")).to_have_class(re.compile(r"\bunknown\b"))
    expect(signal(page, 20, "01")).to_have_attribute("data-aspect", "")
    bench.do(lambda: bench.start_rig(20, Mode.CENTER))
    expect(page.locator("#card-20 .link")).to_have_text("link up")
    expect(tc(page, "TC2055")).not_to_have_class(re.compile(r"\bunknown\b"))


def test_link_monitor_shows_the_taps_frames_in_the_fig7_console_style(
    page: Any, bench: Bench
) -> None:
    page.select_option("#tap-select", index=1)
    expect(page.locator("#monitor-status")).to_contain_text("ktcs-type2")
    frames = page.locator("#monitor-frames pre")
    expect(frames.first).to_be_visible()
    # the CTC asks station 18 for its full state: REQUEST_ALL, then INDICATION parts whose codes
    # are named from station 18's chart (the station was learnt from the link's IDENT frame)
    bench.do(lambda: bench.ctc.request_all(18))
    expect(page.locator("#monitor-frames")).to_contain_text("REQUEST_ALL")
    expect(page.locator("#monitor-frames")).to_contain_text("INDICATION")
    expect(page.locator("#monitor-frames")).to_contain_text("LOC18")
    expect(page.locator("#monitor-frames")).to_contain_text("Packet = [")
    expect(page.locator("#monitor-frames")).to_contain_text(re.compile(r"\[02\]\[[0-9A-F]{2}\]"))
    # new traffic streams in: a control on station 18 appears as CONTROL + CONTROL_RESULT
    page.click('#tools button[data-tool="reverse"]')
    page.locator("#pt-18-32 .pt-dot").click()
    expect(page.locator("#monitor-frames")).to_contain_text("CONTROL_RESULT")
    expect(page.locator("#monitor-frames")).to_contain_text("SRC1832")
    expect(page.locator("#monitor-frames")).to_contain_text("SNR1832")
    page.click('#tools button[data-tool="normal"]')
    page.locator("#pt-18-32 .pt-dot").click()
    expect(page.locator("#pt-18-32")).to_have_attribute("data-position", "normal")


def test_speed_distance_panel_draws_the_trains_curves(page: Any, bench: Bench) -> None:
    # the first train's panel comes up without a choice (a lab with trains shows one at once)
    expect(page.locator("#train-select")).to_have_value("T1")
    expect(page.locator("#speed-status")).to_contain_text("train T1: front")
    page.select_option("#train-select", "T1")
    speed = bench.train.state.speed * 3.6
    expect(page.locator("#speed-status")).to_contain_text("train T1: front")
    expect(page.locator("#speed-status")).to_contain_text(f"{speed:.1f} km/h")
    for name in ("mrsp", "ebi", "sbi", "permitted"):
        line = page.locator(f'#speed-plot polyline[data-curve="{name}"]')
        expect(line).to_have_count(1)
        assert len(line.get_attribute("points").split()) > 100
    expect(page.locator("#speed-plot circle.actual")).to_have_count(1)
    # EBI lies on or above SBI, SBI on or above permitted (smaller y = faster) at every sample
    ys = page.evaluate(
        """() => Object.fromEntries(['ebi', 'sbi', 'permitted'].map((n) => [n,
             document.querySelector(`#speed-plot polyline[data-curve="${n}"]`)
               .getAttribute('points').split(' ').map((p) => Number(p.split(',')[1]))]))"""
    )
    assert all(e <= s + 1e-6 for e, s in zip(ys["ebi"], ys["sbi"], strict=True))
    assert all(s <= p + 1e-6 for s, p in zip(ys["sbi"], ys["permitted"], strict=True))
    # a picture of every panel at work, for people
    page.select_option("#tap-select", index=1)
    expect(page.locator("#monitor-frames")).to_contain_text("Packet = [")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "panels.png"
    page.screenshot(path=str(shot), full_page=True)
    print(f"\nconsole screenshot: {shot}")


def test_the_diagram_labels_each_train_at_its_front_and_moves_it_as_it_runs(
    page: Any, bench: Bench
) -> None:
    label = '#diagram g.train[data-train="T1"] text.train-label'
    expect(page.locator(label)).to_have_text("T1")

    def front_x() -> float:
        ep = bench.train
        head = ep.state.position
        return bench.console.layout.place(head, head - ep.cfg.params.length).head_x

    def label_at(x: float) -> None:
        page.wait_for_function(
            "([sel, x]) => Math.abs(Number(document.querySelector(sel).getAttribute('x')) - x)"
            " < 0.2",
            arg=[label, x],
        )

    before = bench.do(front_x)
    label_at(before)
    # the train runs on for 5 s: its label follows its front along the line
    ep = bench.train

    def run() -> float:
        for i in range(50):
            ep.step(100.0 + i * 0.1, CycleInputs(authority_end=2500.0))
        return front_x()

    after = bench.do(run)
    assert after > before + 10.0
    label_at(after)
    expect(page.locator('#diagram g.train[data-train="T1"] line.train-body')).to_have_count(1)


def test_console_without_taps_or_trains_says_so(browser_context: Any, bench: Bench) -> None:
    pg = browser_context.new_page()
    try:
        pg.goto(bench.bare.url)
        expect(pg.locator("#conn")).to_have_class("up")
        expect(pg.locator("#monitor-frames")).to_contain_text("No taps")
        expect(pg.locator("#speed-status")).to_contain_text("No train registered")
        expect(pg.locator("#card-18 .link")).to_have_text("link up")
    finally:
        pg.close()


def interval(page: Any, name: str) -> Any:
    return page.locator(f"#iv-{name}")


def test_each_interval_draws_an_arrow_of_its_direction_and_a_neutral_mark_without_one(
    page: Any, bench: Bench
) -> None:
    """Each interval's arrow keeps the head of the direction its stations indicate (as the
    CTC's model reads both ends); a lab-edge interval names the station outside the lab as its
    holder; an interval no end is known of shows the dashed shaft alone, "no direction"."""
    for iv in bench.line.intervals:
        shown = bench.do(lambda name=iv.name: bench.model.interval(name))
        if shown.direction in ("up", "down"):
            other = "down" if shown.direction == "up" else "up"
            expect(interval(page, iv.name)).to_have_attribute("data-direction", shown.direction)
            expect(interval(page, iv.name).locator(f".iv-head.{shown.direction}")).to_be_visible()
            expect(interval(page, iv.name).locator(f".iv-head.{other}")).to_be_hidden()
        else:
            expect(interval(page, iv.name)).to_have_attribute("data-direction", "")
            expect(interval(page, iv.name).locator(".iv-head.up")).to_be_hidden()
            expect(interval(page, iv.name).locator(".iv-head.down")).to_be_hidden()
    expect(interval(page, "2224")).to_have_attribute("data-direction", "down")
    expect(interval(page, "2224").locator(".iv-dir")).to_have_text("held by 24")
    bench.call(bench.rigs[22].close())  # the only station 2224 borders: nothing known of it
    expect(interval(page, "2224")).to_have_class(re.compile(r"\bnone\b"))
    expect(interval(page, "2224").locator(".iv-head")).to_have_count(2)
    expect(interval(page, "2224").locator(".iv-head.down")).to_be_hidden()
    expect(interval(page, "2224").locator(".iv-dir")).to_have_text("no direction")
    bench.do(lambda: bench.start_rig(22, Mode.LOCAL))
    expect(interval(page, "2224")).to_have_attribute("data-direction", "down")
