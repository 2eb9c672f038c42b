"""The device kinds of a lab, in one table (python-can's interface registry is the model).

A kind -- `ctc`, `ixl`, `atc`, `trackside`, `trackcircuit`, `train` -- is one row of `KINDS`: the
role its device plays on a link (`--link ROLE=...`, the IXL's name for that peer), the link type
between it and the station's IXL, whether it belongs to a station, the key of its `external:`
address in a lab file, the group it starts in, whether the conformance suite plays against it,
and where its builder is (a dotted path, imported when a device is built: this module stays at
the bottom of the import layering, beside `errors`, and imports nothing of the bench).

The IXL is the hub of a station: every other station kind is one of its peers, and each peer link
carries two code charts, `ixl_to_ROLE` and `ROLE_to_ixl` (`chart_name`). A new kind is one row
here, its core and its emulator, and its builder; every layer reads the rest from this table.

The trackside is `trackside` wherever a kind is named (lab files, `ktcs-bench emulator
trackside`, `--link trackside=...`, the docs); `io` is only its link role, the word the IXL's side
of the link uses, kept because users' files and tools carry it: the charts `ixl_to_io` and
`io_to_ixl` (and their files), the taps and devices of the shipped labs (`st20-io`, `io20`), the
`io` of a status's links and of the IXL's events ("io link up"). `--link io=...` and `--link
trackside=...` are the same (`link_role`).

Must not import anything of `ktcs_bench`: every layer imports it.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from typing import Any

# the kinds, spelled once (every other module names them through these)
CTC = "ctc"
IXL = "ixl"
ATC = "atc"
TRACKSIDE = "trackside"
TRACKCIRCUIT = "trackcircuit"
TRAIN = "train"

IO = "io"
"""The trackside's link role: the IXL's name for its trackside peer (`--link io=...`, the charts
`ixl_to_io`/`io_to_ixl`, `st20-io` taps in the shipped labs)."""

WEST, EAST = "west", "east"
NEIGHBOUR_ROLES: tuple[str, ...] = (WEST, EAST)
"""The IXL's link roles to its neighbouring IXLs (SPEC §6.6): the one at the west end of the
interval between them is its `east` peer's `west`. A vital Type I link per pair of stations, its
charts `ixl_to_east`/`east_to_ixl` (and `..._west`), carrying each shared interval's traffic
permission; not a kind of its own (the peer is an IXL)."""


def neighbour_role(west_end: bool) -> str:
    """The role an IXL gives its neighbour across an interval (SPEC §6.6): `east` when the IXL
    is at the interval's west end (`Interval.west`), else `west`."""
    return EAST if west_end else WEST


def opposite_role(role: str) -> str:
    """What the neighbour calls this IXL: `west` for `east` and the other way round."""
    return WEST if role == EAST else EAST


RAILS = "rails"
"""The bench's own link from a device to the track-circuit emulator (not a kTCS protocol)."""

TYPE1, TYPE2 = "type1", "type2"


@dataclass(frozen=True, slots=True)
class Kind:
    """One device kind: what every layer needs to know of it."""

    name: str
    role: str
    """Its role on a link: the `--link ROLE=...` peer name others give it."""
    label: str
    """How the charts' direction column names it ("IXL->IO")."""
    link: str | None
    """The link type between it and the station's IXL (None: no IXL link)."""
    station: bool
    """It belongs to a station (`--station`)."""
    external: str | None
    """The key of its `external:` address in a lab file (None: never external)."""
    start: int
    """Its start group: a lab starts lower groups first (`lab.runner.start_in_order`)."""
    conformance: bool
    """The conformance suite tests a device of this kind (`--role KIND`)."""
    rails: bool
    """It reaches the track-circuit emulator over the rails."""
    single: bool
    """A lab has at most one."""
    builder: str
    """`module:function` building its device from `ktcs-bench emulator` arguments."""

    @property
    def charts(self) -> tuple[str, str] | None:
        """Its link's charts with the IXL, (IXL->it, it->IXL); None: no IXL link."""
        if self.link is None:
            return None
        return chart_name(self.role, outward=True), chart_name(self.role, outward=False)

    def build(self, *args: Any, **kwargs: Any) -> Any:
        """Its device, built by its builder (imported now)."""
        module, _, func = self.builder.partition(":")
        return getattr(import_module(module), func)(*args, **kwargs)


_B = "ktcs_bench.emulator.build:"

KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        #    name          role          label    link   station external start conf.  rails  single
        Kind(CTC,          CTC,          "CTC",   TYPE2, False, "address", 0, True,  False, True,
             _B + "build_ctc"),
        Kind(IXL,          IXL,          "IXL",   None,  True,  "address", 2, True,  False, False,
             _B + "build_ixl"),
        Kind(ATC,          ATC,          "ATC",   TYPE1, True,  "serial",  1, True,  True,  False,
             _B + "build_atc"),
        Kind(TRACKSIDE,    IO,           "IO",    TYPE1, True,  "serial",  1, True,  True,  False,
             _B + "build_trackside"),
        Kind(TRACKCIRCUIT, TRACKCIRCUIT, "TC",    None,  False, None,      0, False, False, True,
             _B + "build_trackcircuit"),
        Kind(TRAIN,        TRAIN,        "TRAIN", None,  False, None,      3, False, True,  False,
             _B + "build_train"),
    )
}  # fmt: skip
"""Every kind, in the order the help and the docs list them."""

NAMES: tuple[str, ...] = tuple(KINDS)
STATION_KINDS: tuple[str, ...] = tuple(k.name for k in KINDS.values() if k.station)
CONFORMANCE_KINDS: tuple[str, ...] = tuple(k.name for k in KINDS.values() if k.conformance)

IXL_PEERS: tuple[Kind, ...] = tuple(k for k in KINDS.values() if k.link is not None)
"""The kinds an IXL links with, Type II first (the CTC), then its Type I peers."""

TYPE1_ROLES: tuple[str, ...] = tuple(k.role for k in IXL_PEERS if k.link == TYPE1)
"""The IXL's Type I link roles ("atc", "io")."""

PEER_ROLES: tuple[str, ...] = tuple(k.role for k in IXL_PEERS)
"""Every role the IXL gives a peer ("ctc", "atc", "io"): one chart each way."""

LINK_ROLES: tuple[str, ...] = (
    *(k.role for k in KINDS.values() if k.link is not None or k.name == IXL),
    *NEIGHBOUR_ROLES,
    RAILS,
)
"""Every peer name `--link` takes: the IXL, its peers, its neighbouring IXLs, the rails."""


def externals(key: str) -> tuple[str, ...]:
    """The kinds whose `external:` address is given by `key` ("serial" or "address")."""
    return tuple(k.name for k in KINDS.values() if k.external == key)


def role_of(kind: str) -> str:
    """The role a device of `kind` plays on a link ("" for no kind)."""
    k = KINDS.get(kind)
    return k.role if k is not None else ""


def link_role(word: str) -> str:
    """The link role `word` names on input (`--link WORD=...`): a role, or the name of a kind
    that has one (`trackside` for `io`); "" when it names none."""
    if word in LINK_ROLES:
        return word
    k = KINDS.get(word)
    return k.role if k is not None and k.role in LINK_ROLES else ""


def chart_name(role: str, outward: bool) -> str:
    """The chart of the IXL's link with `role`: "ixl_to_ROLE" (outward) or "ROLE_to_ixl"."""
    return f"{IXL}_to_{role}" if outward else f"{role}_to_{IXL}"


def charts() -> tuple[tuple[str, str, str], ...]:
    """(chart, link type, direction) of every station link, peer by peer, each way."""
    out: list[tuple[str, str, str]] = []
    for k in IXL_PEERS:
        assert k.link is not None and k.charts is not None
        outward, inward = k.charts
        out.append((outward, k.link, f"IXL->{k.label}"))
        out.append((inward, k.link, f"{k.label}->IXL"))
    return tuple(out)
