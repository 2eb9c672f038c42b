"""Which shipped profile a stretch of bytes speaks: each profile of a protocol decodes the same
bytes side by side and the one whose frames check most often wins (`decode --profile auto`,
`replay` of a capture that names none)."""

from __future__ import annotations

from ktcs_bench.codec.frame import Frame, Record
from ktcs_bench.codec.profile import FrameProfile, get_profile, profile_names
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.errors import UsageError

DECODE_SLICE = 64 << 10  # bytes decoded at a time: one slice's records are held, not the input's


def decode_all(data: bytes, profile: FrameProfile) -> list[Record]:
    dec = StreamDecoder(profile)
    return dec.feed(data) + dec.close()


class ProfileVote:
    """The same bytes decoded by each shipped profile of a protocol side by side, counting the
    frames whose checks pass; the one with the most wins (ties: the one listed first)."""

    def __init__(self, protocol: str) -> None:
        names = profile_names(None if protocol == "auto" else protocol)
        if not names:
            raise UsageError(f"no shipped profile for protocol {protocol}")
        self.profiles = [get_profile(n) for n in names]
        self._decoders = [StreamDecoder(p) for p in self.profiles]
        self.good = dict.fromkeys(names, 0)
        self.seen = 0

    def feed(self, data: bytes | bytearray) -> None:
        self.seen += len(data)
        with memoryview(data) as view:
            for prof, dec in zip(self.profiles, self._decoders, strict=True):
                for at in range(0, len(data), DECODE_SLICE):  # a slice's records at a time
                    self.good[prof.name] += _good(dec.feed(view[at : at + DECODE_SLICE]))

    def close(self) -> None:
        for prof, dec in zip(self.profiles, self._decoders, strict=True):
            self.good[prof.name] += _good(dec.close())

    def winner(self) -> FrameProfile:
        best = max(self.good.values())
        return next(p for p in self.profiles if self.good[p.name] == best)


def _good(records: list[Record]) -> int:
    return sum(1 for r in records if isinstance(r, Frame) and r.error is None)


def choose_profile(data: bytes, protocol: str) -> tuple[FrameProfile, list[Record], dict[str, int]]:
    """The profile whose CRC checks most often over all of `data`, its records and the counts."""
    vote = ProfileVote(protocol)
    vote.feed(data)
    vote.close()
    profile = vote.winner()
    return profile, decode_all(data, profile), vote.good
