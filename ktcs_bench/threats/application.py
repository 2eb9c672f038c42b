"""What the application did under a threat, read over our emulators' control ports: the IXL's
status (links, occupied track circuits, point detection), the CTC's view of the station, the CTC's
log. A real device has no such port; then the outcome is "not observed" and the wire verdict stands
alone, said so in the report.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict, cast

from ktcs_bench import kinds
from ktcs_bench import messages as msg
from ktcs_bench.ctc.model import StationSummary
from ktcs_bench.errors import UsageError
from ktcs_bench.lab.state import lab_dir, running_labs
from ktcs_bench.lab.topology import load_lab
from ktcs_bench.lab.view import LinkEntry
from ktcs_bench.station.model import Line
from ktcs_bench.station_codes.chart import CodeChart
from ktcs_bench.station_codes.names import Function
from ktcs_bench.station_codes.stations import StationCodes, station_chart
from ktcs_bench.transport import jsonlines

ASK_TIMEOUT = 5.0


class IxlInputs(TypedDict, total=False):
    """What a threat reads of an IXL's status (`emulator.ixl.IxlDevice.status`, which says
    more): its links up by peer role, the track circuits it takes as occupied, each point's
    detection, its indication table to the CTC (code number as text -> value)."""

    links: dict[str, bool]
    occupied: list[str]
    points: dict[str, str]
    ctc_state: dict[str, int]


class CtcView(TypedDict, total=False):
    """The CTC's answer to `show` (`messages.ShowAnswer`): the station's summary and its
    indication table by code name (each read where it is used)."""

    ok: bool
    summary: StationSummary
    state: dict[str, int]


def host_port(text: str) -> tuple[str, int]:
    """`HOST:PORT` as a device's ready line gives it -> (host, port)."""
    host, _, port = text.rpartition(":")
    return host, int(port)


@dataclass
class Application:
    """The devices behind one tapped link. `role` is the IXL's name for its Type I peer (atc, io);
    `guarded` the codes the IXL must take as unsafe while that link is lost; `probe` the code the
    insertion and corruption frames name. Empty (`Application()`): nothing can be read."""

    ixl: tuple[str, int] | None = None
    ctc: tuple[str, int] | None = None
    ctc_log: Path | None = None
    station: int | None = None
    role: str = kinds.ATC
    rx_chart: CodeChart | None = None  # the Type I peer -> IXL chart
    ctc_chart: CodeChart | None = None  # IXL -> CTC
    guarded: tuple[str, ...] = ()
    source: str = ""
    device: str = kinds.IXL  # the IXL's end name on the tapped link
    notes: list[str] = field(default_factory=list)

    @classmethod
    def of_station(cls, line: Line, station: int, role: str = kinds.ATC, **kw: Any) -> Application:
        view = line.view(station)
        rx = station_chart(view, f"{role}_to_ixl")
        guarded: tuple[str, ...] = ()
        if role == kinds.ATC:  # the track circuits: unsafe (occupied) while the ATC link is lost
            codes = StationCodes(view)
            guarded = tuple(
                c.name
                for c in rx.codes
                if (m := codes.parse_code(c.name)) and m.function is Function.TC
            )
        return cls(station=station, role=role, rx_chart=rx,
                   ctc_chart=station_chart(view, "ixl_to_ctc"), guarded=guarded, **kw)  # fmt: skip

    @property
    def readable(self) -> bool:
        return self.ixl is not None

    @property
    def probe(self) -> str | None:
        if self.guarded:
            return self.guarded[0]
        return self.rx_chart.codes[0].name if self.rx_chart and self.rx_chart.codes else None

    # -- reading ---------------------------------------------------------------------------------
    @staticmethod
    def _ask(address: tuple[str, int], obj: msg.Message) -> dict[str, Any]:
        return asyncio.run(jsonlines.request(*address, obj, timeout=ASK_TIMEOUT))

    def ixl_status(self) -> IxlInputs | None:
        if self.ixl is None:
            return None
        return cast(IxlInputs, self._ask(self.ixl, msg.Status())["status"])

    def ctc_view(self) -> CtcView | None:
        if self.ctc is None or self.station is None:
            return None
        return cast(CtcView, self._ask(self.ctc, msg.Show(station=self.station)))

    def link_up(self) -> bool | None:
        s = self.ixl_status()
        return None if s is None else bool(s["links"].get(self.role))

    def failsafe(self, status: IxlInputs) -> bool:
        """While the Type I link is lost: every guarded track circuit occupied (ATC), every point
        without detection (trackside I/O)."""
        if self.role == kinds.ATC:
            return bool(self.guarded) and set(self.guarded) <= set(status["occupied"])
        return all(d == "none" for d in status["points"].values())

    def settled(self, status: IxlInputs) -> bool:
        """The link is up and the IXL's inputs are the true (clear) state again."""
        up = bool(status["links"].get(self.role))
        if self.role == kinds.ATC:
            return up and not set(self.guarded) & set(status["occupied"])
        return up and all(d != "none" for d in status["points"].values())

    def inputs(self) -> tuple[Any, ...] | None:
        """The IXL's view of what its Type I peers report (occupied track circuits, point
        detection): equal before and after a threat means nothing false was kept. None: not
        readable."""
        status = self.ixl_status()
        if status is None:
            return None
        return tuple(sorted(status["occupied"])), tuple(sorted(status["points"].items()))

    def views_agree(self) -> bool | None:
        """The CTC's view of the station equals the IXL's indication state."""
        s, v = self.ixl_status(), self.ctc_view()
        if s is None or v is None or self.ctc_chart is None:
            return None
        ixl = {self.ctc_chart.name_of(int(k)): val for k, val in s["ctc_state"].items()}
        return bool(v["summary"]["synced"] and v["state"] == ixl)

    def ctc_log_text(self) -> str | None:
        if self.ctc_log is None:
            return None
        try:
            return self.ctc_log.read_text(errors="replace")
        except OSError:
            return None


def find_in_labs(tap_name: str, lab_name: str | None = None) -> Application:
    """The devices of the running lab whose link `tap_name` is; `Application()` if none is up."""
    for state in running_labs():
        if lab_name is not None and state.get("lab") != lab_name:
            continue
        link = next((lk for lk in state.get("links", []) if lk.get("link") == tap_name), None)
        if link is None or "a" not in link:
            continue
        return _from_state(state, link)
    if lab_name is not None:
        raise UsageError(f"lab {lab_name} is not up, or has no link named {tap_name!r}")
    return Application()


def _from_state(state: dict[str, Any], link: LinkEntry) -> Application:
    lab = load_lab(Path(state["file"]))
    devices = state.get("devices", {})
    ixl_name = link["a"] if lab.devices[link["a"]].kind == kinds.IXL else link["b"]
    ixl_spec = lab.devices[ixl_name]
    if ixl_spec.station is None or ixl_name not in devices:
        return Application()
    ctc_name = next((d.name for d in lab.of_kind(kinds.CTC) if d.name in devices), None)
    spec = next(lk for lk in lab.links if lk.name == link["link"])
    role = lab.peer_role(spec, ixl_name) if spec.type == "type1" else kinds.ATC
    return Application.of_station(
        lab.load_line(), ixl_spec.station, role,
        ixl=host_port(devices[ixl_name]["control"]),
        ctc=host_port(devices[ctc_name]["control"]) if ctc_name else None,
        ctc_log=lab_dir(str(state["lab"])) / "logs" / f"{ctc_name}.log" if ctc_name else None,
        source=f"lab {state['lab']} (devices {ixl_name}" + (f", {ctc_name})" if ctc_name else ")"),
        device=ixl_name,
    )  # fmt: skip
