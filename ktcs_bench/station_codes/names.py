"""Code names (seed 004 Tables 1-3): function code, then devices, then status.

The one place that spells a code name and the one place that takes one apart, so the charts, the
IXL, the trackside, the ATC and the CTC cannot disagree. A name is its function (the mnemonic), the
station number, the object (point, signal, route) and, for a lamp or aspect code, the aspect:
`SNI1831` is point 31 of station 18, `ASP1801G` signal 01 of station 18 showing G, `RSC180111`
"set route 01-11 of station 18". Three kinds are spelled otherwise: a track circuit is named with
its station already (`TC1853A`); an interval code names the interval, west station then east
(`IZC1820`, `TDU1820`); a totaliser names the first and last track circuits it totals without
their `TC` (`TTC1861A1867` over TC1861A..TC1867).

`CodeName` is a name taken apart; its `text` is the name. Which names a station has, and so what a
name means (`StationCodes.parse_code`), comes from the station data (`station_codes.stations`): a
name cannot be split by reading it alone, since neither station numbers nor aspects have a fixed
length.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from functools import cache


class Function(StrEnum):
    """The mnemonic a code name starts with; also the chart's `type` column."""

    # station mode (Table 3) and its controls
    LOC = "LOC"  # local mode
    CTC = "CTC"  # center mode
    CMR = "CMR"  # center mode requested, awaiting the local operator
    CMQ = "CMQ"  # CTC -> IXL: request center mode
    LMQ = "LMQ"  # CTC -> IXL: hand the station back to local mode
    # points
    SNI = "SNI"  # detected normal
    SRN = "SRN"  # moving reverse -> normal
    SRI = "SRI"  # detected reverse
    SNR = "SNR"  # moving normal -> reverse
    SLI = "SLI"  # locked by a route
    SFI = "SFI"  # failed: no detection
    SNC = "SNC"  # CTC -> IXL: to normal
    SRC = "SRC"  # CTC -> IXL: to reverse
    PNC = "PNC"  # IXL -> trackside: normal demanded (a level)
    PRC = "PRC"  # IXL -> trackside: reverse demanded
    # signals
    ASP = "ASP"  # showing an aspect
    SSI = "SSI"  # held at stop by the CTC
    LFI = "LFI"  # lamp failure
    SSC = "SSC"  # CTC -> IXL: hold at stop (1) or release (0)
    SGP = "SGP"  # IXL -> ATC: at proceed
    SGC = "SGC"  # IXL -> trackside: light an aspect (one-hot per signal)
    LPS = "LPS"  # trackside -> IXL: the lamp of an aspect lit and proved
    # routes
    RSI = "RSI"  # set and locked
    ALI = "ALI"  # approach locked: the timed release is running
    RSC = "RSC"  # CTC -> IXL: set
    RCC = "RCC"  # CTC -> IXL: cancel
    RLI = "RLI"  # IXL -> ATC: set and locked, train not yet past its entry signal
    # intervals and track circuits
    TDU = "TDU"  # traffic direction up
    TDD = "TDD"  # traffic direction down
    IZC = "IZC"  # interval occupied (its totalisers)
    # an interval's traffic permission (SPEC §6.6): IXL <-> IXL, and to the CTC
    PHI = "PHI"  # the sender holds the interval's traffic permission
    PRQ = "PRQ"  # the sender asks for the permission
    DRL = "DRL"  # a departure route of the sender's into the interval is locked
    DRC = "DRC"  # CTC -> IXL: ask the neighbour for the interval's permission
    TTC = "TTC"  # totaliser over a run of track circuits: occupied
    TC = "TC"  # track circuit occupied


STATION_FUNCTIONS = frozenset(
    {Function.LOC, Function.CTC, Function.CMR, Function.CMQ, Function.LMQ}
)
INTERVAL_FUNCTIONS = frozenset(
    {
        Function.TDU,
        Function.TDD,
        Function.IZC,
        Function.PHI,
        Function.PRQ,
        Function.DRL,
        Function.DRC,
    }
)
ASPECT_FUNCTIONS = frozenset({Function.ASP, Function.SGC, Function.LPS})


@dataclass(frozen=True, slots=True)
class CodeName:
    """A code name taken apart. `station` is None for an interval code (both neighbours carry it);
    `object` is the point, signal or route name, the interval name (interval codes and
    totalisers), the track circuit's own name (TC), or empty (station mode codes); `aspect` only
    for ASP, SGC and LPS; `track_circuits` only for a totaliser (TTC), the run it totals."""

    function: Function
    station: int | None = None
    object: str = ""
    aspect: str = ""
    track_circuits: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        """The name as the charts, the links and the operator spell it."""
        f = self.function
        if f is Function.TC:
            return self.object
        if f is Function.TTC:
            first, last = self.track_circuits[0], self.track_circuits[-1]
            return f"TTC{first.removeprefix('TC')}{last.removeprefix('TC')}"
        if f in INTERVAL_FUNCTIONS:
            return f"{f}{self.object}"
        return f"{f}{self.station}{self.object}{self.aspect}"

    def __str__(self) -> str:
        return self.text


@cache
def _on(function: Function, st: int, obj: str = "", aspect: str = "") -> str:
    """A station code's name, spelt once (the devices ask for the same few hundred names on
    every status, code and route check)."""
    return CodeName(function, st, obj, aspect).text


@cache
def _of_interval(function: Function, interval: str) -> str:
    return CodeName(function, None, interval).text


# station mode (Table 3)
def loc(st: int) -> str:
    return _on(Function.LOC, st)


def ctc(st: int) -> str:
    return _on(Function.CTC, st)


def cmr(st: int) -> str:
    return _on(Function.CMR, st)


def cmq(st: int) -> str:
    """CTC -> IXL: center mode request."""
    return _on(Function.CMQ, st)


def lmq(st: int) -> str:
    """CTC -> IXL: hand the station back to local control."""
    return _on(Function.LMQ, st)


# points: indications (Table 3) and controls
def sni(st: int, p: str) -> str:
    return _on(Function.SNI, st, p)


def srn(st: int, p: str) -> str:
    return _on(Function.SRN, st, p)


def sri(st: int, p: str) -> str:
    return _on(Function.SRI, st, p)


def snr(st: int, p: str) -> str:
    return _on(Function.SNR, st, p)


def sli(st: int, p: str) -> str:
    """Point locked by a route."""
    return _on(Function.SLI, st, p)


def sfi(st: int, p: str) -> str:
    """Point failed: no detection."""
    return _on(Function.SFI, st, p)


def snc(st: int, p: str) -> str:
    """CTC -> IXL: point to normal."""
    return _on(Function.SNC, st, p)


def src(st: int, p: str) -> str:
    """CTC -> IXL: point to reverse."""
    return _on(Function.SRC, st, p)


def pnc(st: int, p: str) -> str:
    """IXL -> trackside: point normal command (level: 1 while normal is demanded)."""
    return _on(Function.PNC, st, p)


def prc(st: int, p: str) -> str:
    """IXL -> trackside: point reverse command."""
    return _on(Function.PRC, st, p)


# signals
def asp(st: int, s: str, aspect: str) -> str:
    """Signal showing `aspect` (R, W, Y, YG, G)."""
    return _on(Function.ASP, st, s, aspect)


def ssi(st: int, s: str) -> str:
    """Signal held at stop by the CTC."""
    return _on(Function.SSI, st, s)


def lfi(st: int, s: str) -> str:
    """Signal lamp failure."""
    return _on(Function.LFI, st, s)


def ssc(st: int, s: str) -> str:
    """CTC -> IXL: signal stop (1 hold at stop, 0 release)."""
    return _on(Function.SSC, st, s)


def sgp(st: int, s: str) -> str:
    """IXL -> ATC: signal at proceed."""
    return _on(Function.SGP, st, s)


def sgc(st: int, s: str, aspect: str) -> str:
    """IXL -> trackside: light `aspect` (one-hot per signal)."""
    return _on(Function.SGC, st, s, aspect)


def lps(st: int, s: str, aspect: str) -> str:
    """Trackside -> IXL: lamp of `aspect` lit and proved."""
    return _on(Function.LPS, st, s, aspect)


# routes
def rsi(st: int, r: str) -> str:
    """Route set (locked) indication."""
    return _on(Function.RSI, st, r)


def ali(st: int, r: str) -> str:
    """Approach locking: the route's timed release is running."""
    return _on(Function.ALI, st, r)


def rsc(st: int, r: str) -> str:
    """CTC -> IXL: set route."""
    return _on(Function.RSC, st, r)


def rcc(st: int, r: str) -> str:
    """CTC -> IXL: cancel route."""
    return _on(Function.RCC, st, r)


def rli(st: int, r: str) -> str:
    """IXL -> ATC: route set and locked, train not yet past its entry signal."""
    return _on(Function.RLI, st, r)


# intervals
def tdu(interval: str) -> str:
    """Traffic direction up established in the interval."""
    return _of_interval(Function.TDU, interval)


def tdd(interval: str) -> str:
    return _of_interval(Function.TDD, interval)


def izc(interval: str) -> str:
    return _of_interval(Function.IZC, interval)


def phi(interval: str) -> str:
    """The sender holds the interval's traffic permission (IXL -> IXL, IXL -> CTC)."""
    return _of_interval(Function.PHI, interval)


def prq(interval: str) -> str:
    """The sender asks its neighbour for the interval's permission (IXL -> IXL, IXL -> CTC)."""
    return _of_interval(Function.PRQ, interval)


def drl(interval: str) -> str:
    """A departure route of the sender's into the interval is locked (IXL -> IXL)."""
    return _of_interval(Function.DRL, interval)


def drc(interval: str) -> str:
    """CTC -> IXL: ask the neighbour for the interval's permission ahead of a route."""
    return _of_interval(Function.DRC, interval)
