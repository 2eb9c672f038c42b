"""A generated line runs for real: `lab up` on the lab file `line generate` wrote starts every
device as its own process, and every station comes up synced at the CTC in center mode with its
Type I and Type II links up."""

from __future__ import annotations

from pathlib import Path

from ktcs_bench.lab.generate import write_line
from tests.lab.conftest import start_lab, wait_until


def test_generated_three_station_lab_comes_up_in_center_mode_with_links_up(
    tmp_path: Path,
) -> None:
    write_line(3, tmp_path / "line3")
    with start_lab(tmp_path, "line3", path=tmp_path / "line3" / "lab.yaml") as lab:

        def every_station_up() -> bool:
            stations = lab.ctc({"cmd": "status"})["status"]["stations"]
            return sorted(stations) == ["12", "14", "16"] and all(
                s["link"] == "up" and s["synced"] and s["mode"] == "center" and not s["occupied"]
                for s in stations.values()
            )

        wait_until("stations 12, 14, 16 synced at the CTC in center mode", every_station_up)
        for st in (12, 14, 16):
            ixl = wait_until(
                f"ixl{st}: center mode, ATC, trackside and CTC links up",
                lambda st=st: (
                    (s := lab.status(f"ixl{st}"))["mode"] == "center"
                    and s["links"] == {"atc": True, "io": True, "ctc": True}
                    and s
                ),
            )
            assert ixl["station"] == st
            assert lab.status(f"atc{st}")["kind"] == "atc"
            assert lab.status(f"io{st}")["kind"] == "trackside"
        links = {f"st{st}-{end}" for st in (12, 14, 16) for end in ("ctc", "atc", "io")}
        assert links <= set(lab.links)
        assert all("tap" in lab.links[name] for name in links)  # every link through its tap
