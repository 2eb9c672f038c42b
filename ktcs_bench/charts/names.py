"""Code mnemonics (seed 004 Tables 1-3): function code, then devices, then status.

The one place that spells a code name, so the chart generator, the IXL, the trackside and the ATC
cannot disagree. Devices are the station number then the object: `SNI1831` is point 31 of
station 18, `ASP1801G` signal 01 of station 18 showing G, `RSC180111` "set route 01-11 of station
18", `TC1853A` a track circuit (already named with its station), `TTC1861A1867` the totaliser over
TC1861A..TC1867, `IZC1820` the interval zone between stations 18 and 20.
"""

from __future__ import annotations


# station mode (Table 3)
def loc(st: int) -> str:
    return f"LOC{st}"


def ctc(st: int) -> str:
    return f"CTC{st}"


def cmr(st: int) -> str:
    return f"CMR{st}"


def cmq(st: int) -> str:
    """CTC -> IXL: center mode request."""
    return f"CMQ{st}"


def lmq(st: int) -> str:
    """CTC -> IXL: hand the station back to local control."""
    return f"LMQ{st}"


# points: indications (Table 3) and controls
def sni(st: int, p: str) -> str:
    return f"SNI{st}{p}"


def srn(st: int, p: str) -> str:
    return f"SRN{st}{p}"


def sri(st: int, p: str) -> str:
    return f"SRI{st}{p}"


def snr(st: int, p: str) -> str:
    return f"SNR{st}{p}"


def sli(st: int, p: str) -> str:
    """Point locked by a route."""
    return f"SLI{st}{p}"


def sfi(st: int, p: str) -> str:
    """Point failed: no detection."""
    return f"SFI{st}{p}"


def snc(st: int, p: str) -> str:
    """CTC -> IXL: point to normal."""
    return f"SNC{st}{p}"


def src(st: int, p: str) -> str:
    """CTC -> IXL: point to reverse."""
    return f"SRC{st}{p}"


def pnc(st: int, p: str) -> str:
    """IXL -> trackside: point normal command (level: 1 while normal is demanded)."""
    return f"PNC{st}{p}"


def prc(st: int, p: str) -> str:
    """IXL -> trackside: point reverse command."""
    return f"PRC{st}{p}"


# signals
def asp(st: int, s: str, aspect: str) -> str:
    """Signal showing `aspect` (R, W, Y, YG, G)."""
    return f"ASP{st}{s}{aspect}"


def ssi(st: int, s: str) -> str:
    """Signal held at stop by the CTC."""
    return f"SSI{st}{s}"


def lfi(st: int, s: str) -> str:
    """Signal lamp failure."""
    return f"LFI{st}{s}"


def ssc(st: int, s: str) -> str:
    """CTC -> IXL: signal stop (1 hold at stop, 0 release)."""
    return f"SSC{st}{s}"


def sgp(st: int, s: str) -> str:
    """IXL -> ATC: signal at proceed."""
    return f"SGP{st}{s}"


def sgc(st: int, s: str, aspect: str) -> str:
    """IXL -> trackside: light `aspect` (one-hot per signal)."""
    return f"SGC{st}{s}{aspect}"


def lps(st: int, s: str, aspect: str) -> str:
    """Trackside -> IXL: lamp of `aspect` lit and proved."""
    return f"LPS{st}{s}{aspect}"


# routes
def rsi(st: int, r: str) -> str:
    """Route set (locked) indication."""
    return f"RSI{st}{r}"


def ali(st: int, r: str) -> str:
    """Approach locking: the route's timed release is running."""
    return f"ALI{st}{r}"


def rsc(st: int, r: str) -> str:
    """CTC -> IXL: set route."""
    return f"RSC{st}{r}"


def rcc(st: int, r: str) -> str:
    """CTC -> IXL: cancel route."""
    return f"RCC{st}{r}"


def rli(st: int, r: str) -> str:
    """IXL -> ATC: route set and locked, train not yet past its entry signal."""
    return f"RLI{st}{r}"


# intervals and track circuits
def tdu(interval: str) -> str:
    """Traffic direction up established in the interval."""
    return f"TDU{interval}"


def tdd(interval: str) -> str:
    return f"TDD{interval}"


def izc(interval: str) -> str:
    return f"IZC{interval}"


def ttc(first_tc: str, last_tc: str) -> str:
    """Totaliser over track circuits first..last: `TTC` + both names without their `TC`."""
    return f"TTC{first_tc.removeprefix('TC')}{last_tc.removeprefix('TC')}"
