"""`ktcs-bench decode`: hex text in any common form -> frames with every field and the CRC verdict.

It streams: the input is read a block at a time, each block's lines parsed, decoded and printed
before the next is read, so memory stays bounded whatever the input's size. `--profile auto`
decides on the first frames (a bounded window), then streams the rest with the profile chosen.
"""

from __future__ import annotations

import argparse
import codecs
import math
import re
import sys
from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from ktcs_bench.chart_files.files import load_chart
from ktcs_bench.codec.frame import Frame, Record
from ktcs_bench.codec.hextext import TEXT_WINDOW, Chunk, HexTextParser, TextWatch, text_encoding
from ktcs_bench.codec.profile import FrameProfile, get_profile, profile_names
from ktcs_bench.codec.render import BOLD, RESET, json_line, payload, to_json, to_text
from ktcs_bench.codec.stream import StreamDecoder
from ktcs_bench.codec.vote import DECODE_SLICE, ProfileVote
from ktcs_bench.errors import UsageError
from ktcs_bench.station_codes.chart import CodeChart

HELP = "decode hex frames (console captures, hex dumps, hex logs) into fields and CRC verdicts"
DESCRIPTION = """\
Decode Type I / Type II frames from hex text. The input is hex in any common form, mixed freely:
  <02><04><00>...      [02][84][00]...      02 04 00 ...      020400...      0x02,0x04,...
  xxd, hexdump -C and od -t x1 dumps (their offset columns are not data), the seed 004 Fig. 7
  console lines ("수신 = <02>...", "송신 = [02]...", wrapped over several lines), and the bench's
  hex logs ("<seconds> <direction> <hex>"). Files may be UTF-8 or CP949/EUC-KR (as Korean
  consoles save them).
Lines that are not hex (console annotations) are skipped. The bytes are decoded as one stream,
so a frame may span lines and garbage between frames is reported with its offset. Any input size
streams in bounded memory; --profile auto decides on the first frames.

An argument is a file when one exists by that name; one that looks like a path (a /, a leading
. or ~, an extension) but does not exist is an error, as is a bare word of hex digits too short to
hold a frame (`decode fade` with no file `fade`; write hex to decode as 'FA DE').
"""
EPILOG = """\
examples:
  ktcs-bench decode protocols/captures/fig7.hex --profile auto
  ktcs-bench decode '02 00 00 10 06 00 03 87 00 00 03'
  ktcs-bench decode --protocol type2 --json '02 03 01 30 00 3C 44'
  xxd capture.bin | ktcs-bench decode --chart code_charts/st20_ixl_to_ctc.yaml

exit status: 0 every frame checks; 1 a frame failed a check (crc, etx, length, truncated, format)
or no frame was found; 2 bad arguments, profile, chart or input file (one that is not text, or
stops being text part-way: the message names the byte where it did).
"""

READ_BLOCK = 1 << 20  # bytes of input read and parsed at a time
AUTO_WINDOW = 256 << 10  # --profile auto decides once this many bytes decoded hold a good frame,
AUTO_WINDOW_MAX = 4 << 20  # or at this many in any case (or at the end of the input),
AUTO_WINDOW_RECORDS = 1 << 16  # or once this many records (lines of a hex log) have begun
_PATHLIKE = re.compile(r"[/\\]|^[.~]|\.[A-Za-z][A-Za-z0-9]{0,7}$")
_BARE_WORD = re.compile(r"[\w-]+")
_HEX_WORD = re.compile(r"(?:[0-9a-fA-F]{2})+")
_HEX_DIGITS = re.compile(r"[0-9a-fA-F]+")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "decode",
        help=HELP,
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="*", metavar="HEX|FILE", help="hex text or a file; '-' stdin")
    p.add_argument(
        "--protocol", choices=("type1", "type2", "auto"), default="auto",
        help="which protocol's profiles to try (default: auto, all of them)",
    )  # fmt: skip
    p.add_argument(
        "--profile", default="auto",
        help="profile name (ktcs-type1, ktcs-type1-fig7, ktcs-type2), FILE.yaml[:NAME] of your own, "
        "or auto: try each on the first frames and take the one whose CRC checks (default)",
    )  # fmt: skip
    p.add_argument("--chart", help="code chart YAML: show code names for items and statuses")
    p.add_argument("--json", action="store_true", help="one JSON object per frame (SPEC §7 keys)")
    p.set_defaults(handler=run)


# -- input --------------------------------------------------------------------------------------
def _check_inputs(inputs: list[str]) -> list[str]:
    """The inputs, refusing (before anything is printed) a file that does not exist."""
    if not inputs:
        if sys.stdin.isatty():
            raise UsageError("no input: give hex text, a capture file, or pipe it on stdin")
        return ["-"]
    bare = [i for i in inputs if not Path(i).exists() and _BARE_WORD.fullmatch(i)]
    bare_bytes = sum(len(i) // 2 for i in bare if _HEX_WORD.fullmatch(i))
    smallest = min(get_profile(n).frame_size(0) for n in profile_names())
    for item in inputs:
        path = Path(item)
        if item == "-" or path.is_file():
            continue
        if path.exists():
            raise UsageError(f"{item} is not a file")
        if _PATHLIKE.search(item):
            raise UsageError(f"no such file: {item}")
        if item in bare and (not _HEX_WORD.fullmatch(item) or bare_bytes < smallest):
            raise UsageError(
                f"no such file: {item} (as hex, the bare words given hold {bare_bytes} bytes, "
                f"fewer than the smallest frame's {smallest}; to decode them, write the bytes "
                "spaced and quoted, e.g. 'FA DE')"
            )
    return inputs


def _binary_lines(stream: BinaryIO, name: str) -> Iterator[list[str]]:
    """The lines of a text file or pipe, a block at a time, in the encoding its head shows. The
    whole input is watched as it streams: where it stops being text, it is refused (exit 2)
    before a line of the block holding that is yielded."""
    block = stream.read1(READ_BLOCK) if hasattr(stream, "read1") else stream.read(READ_BLOCK)
    encoding = text_encoding(block[:TEXT_WINDOW])
    if encoding is None:
        raise UsageError(f"{name} is not text (a binary file?): {_raw_hint(name)}")
    watch = TextWatch(encoding)
    decoder = codecs.getincrementaldecoder(encoding)(errors="replace")
    tail = ""
    while block:
        if (at := watch.feed(block)) is not None:
            raise _not_text_from(name, at)
        lines = (tail + decoder.decode(block)).split("\n")
        tail = lines.pop()
        if len(tail) > READ_BLOCK:  # a line with no end in sight (one long hex string)
            head, tail = _cut_long_line(tail)
            if head:
                lines.append(head)
        yield lines
        block = stream.read1(READ_BLOCK) if hasattr(stream, "read1") else stream.read(READ_BLOCK)
    if (at := watch.close()) is not None:
        raise _not_text_from(name, at)
    rest = tail + decoder.decode(b"", final=True)
    if rest:
        yield [rest]


def _raw_hint(name: str) -> str:
    return (
        "decode reads hex text; "
        f"for raw bytes, `xxd {name if name != 'stdin' else 'FILE'} | ktcs-bench decode`"
    )


def _not_text_from(name: str, at: int) -> UsageError:
    return UsageError(
        f"{name} stops being text at byte {at} (binary from there on, never decoded as hex; "
        f"what was printed before it stands): {_raw_hint(name)}"
    )


def _cut_long_line(text: str) -> tuple[str, str]:
    """A line too long to hold, cut where its rest reads as a continuation line of hex (bare
    hex continues the record its line began): after its last separator, or, in one unbroken run
    of hex digits, at an even count. ("", text) when it cannot be cut (a comment)."""
    if "#" in text:
        return "", text
    cut = max(text.rfind(c) for c in " \t,>]")
    if cut < 0 and _HEX_DIGITS.fullmatch(text):
        cut = len(text) - len(text) % 2 - 1
    return (text[: cut + 1], text[cut + 1 :]) if cut > 0 else ("", text)


def input_lines(inputs: list[str]) -> Iterator[list[str]]:
    """Every input's lines, in order, a block at a time: hex text arguments, files, stdin."""
    for item in inputs:
        if item == "-":
            yield from _binary_lines(sys.stdin.buffer, "stdin")
        elif Path(item).is_file():
            try:
                with open(item, "rb") as f:
                    yield from _binary_lines(f, item)
            except OSError as exc:
                raise UsageError(f"cannot read {item}: {exc.strerror}") from None
        else:
            yield item.splitlines()


# -- output -------------------------------------------------------------------------------------
class _Origins:
    """The origins (line, time, direction) of the records not yet labelled, a chunk of the text
    each, oldest first. Every line of a hex log begins one, and a block of input or the window
    of --profile auto holds many, so they are kept in arrays, not as objects."""

    COMPACT = 4096  # entries passed before they are dropped from the arrays' front

    def __init__(self) -> None:
        self._offsets = array("q")
        self._lines = array("q")
        self._times = array("d")  # nan: none
        self._directions: list[str | None] = []
        self._names: dict[str, str] = {}  # one string per direction name (the first 256)
        self._first = 0  # index of the oldest entry still wanted

    def append(self, chunk: Chunk) -> None:
        self._offsets.append(chunk.offset)
        self._lines.append(chunk.line)
        self._times.append(math.nan if chunk.time is None else chunk.time)
        direction = chunk.direction
        if direction is not None and len(self._names) < 256:
            direction = self._names.setdefault(direction, direction)
        self._directions.append(direction)

    def label(self, offset: int) -> str:
        """The label of a record at stream `offset`: where the chunk holding it began."""
        offsets, k, last = self._offsets, self._first, len(self._offsets) - 1
        while k < last and offsets[k + 1] <= offset:
            k += 1
        if k >= self.COMPACT and 2 * k > last:
            for column in (self._offsets, self._lines, self._times, self._directions):
                del column[:k]
            k = 0
        self._first = k
        if k > last or offsets[k] > offset:
            return ""
        parts = [f"line {self._lines[k]}"]
        if direction := self._directions[k]:
            parts.insert(0, direction)
        if not math.isnan(time := self._times[k]):
            parts.insert(0, f"t={time:.6f}")
        return " ".join(parts) + "  "


class _Output:
    """Records -> text or JSON lines on stdout, a block at a time, and the counts of the summary."""

    def __init__(self, args: argparse.Namespace, chart: CodeChart | None) -> None:
        self.json = bool(args.json)
        self.chart = chart
        self.colour: bool = args.colour  # main decides, for every command
        self.origins = _Origins()  # chunks not yet passed, for the line labels
        self.frames = self.good = self.garbage = 0
        self.failed = False
        self._lines: list[str] = []

    def records(self, records: list[Record], profile: FrameProfile) -> None:
        lines = self._lines
        if self.json:
            for record in records:
                obj = to_json(record, profile)
                if record.__class__ is Frame:
                    self.frames += 1
                    if obj.get("error") is None:
                        self.good += 1
                    else:
                        self.failed = True
                lines.append(json_line(obj))
            return
        for record in records:
            if isinstance(record, Frame):
                self.frames += 1
                if record.error is None and payload(record, profile)[2] is None:
                    self.good += 1
                else:  # a framing error, or a payload that does not parse (JSON: "format")
                    self.failed = True
            else:
                self.garbage += len(record.raw)
            label = self.origins.label(record.offset)
            lines.append(to_text(record, profile, self.chart, self.colour, label))
            lines.append("")

    def decoded(self, decoder: StreamDecoder, data: bytes | bytearray) -> None:
        """Decode `data` and print its records, a slice at a time: what is held at once is one
        slice's records and output, whatever the data's size (a block, the auto window)."""
        with memoryview(data) as view:
            for at in range(0, len(data), DECODE_SLICE):
                self.records(decoder.feed(view[at : at + DECODE_SLICE]), decoder.profile)
                self.flush()

    def line(self, text: str) -> None:
        self._lines.append(text)

    def flush(self) -> None:
        if self._lines:
            self._lines.append("")
            sys.stdout.write("\n".join(self._lines))
            self._lines.clear()
        sys.stdout.flush()


def run(args: argparse.Namespace) -> int:
    profile: FrameProfile | None = None
    if args.profile != "auto":
        profile = get_profile(args.profile)
        if args.protocol != "auto" and profile.protocol != args.protocol:
            raise UsageError(f"profile {profile.name} is {profile.protocol}, not {args.protocol}")
    chart: CodeChart | None = load_chart(args.chart) if args.chart else None
    inputs = _check_inputs(args.inputs)
    out = _Output(args, chart)
    parser = HexTextParser()
    track_origins = not args.json
    vote = ProfileVote(args.protocol) if profile is None else None
    window = bytearray()  # what --profile auto has seen while it decides
    decoder = None if profile is None else StreamDecoder(profile)
    total = 0

    def decide(final: bool) -> None:
        nonlocal profile, decoder
        assert vote is not None
        if final:
            vote.close()
        profile = vote.winner()
        if not args.json:
            counts = ", ".join(f"{n}: {s}" for n, s in vote.good.items())
            scope = "" if final else f" in the first {vote.seen} bytes"
            verdict = (
                "CRC checks" if vote.good[profile.name] else "no profile's CRC checks; showing"
            )
            out.line(f"profile auto: {verdict} {profile.name}  (good frames per profile{scope}: "
                     f"{counts})")  # fmt: skip
        decoder = StreamDecoder(profile)
        out.decoded(decoder, window)
        window.clear()

    for lines in input_lines(inputs):
        block = bytearray()
        feed = parser.feed
        for line in lines:
            pieces = feed(line)
            if track_origins and parser.new_chunk and parser.chunk is not None:
                out.origins.append(parser.chunk)
            for piece in pieces:
                block += piece
        total += len(block)
        if decoder is not None:
            out.decoded(decoder, block)
        else:
            assert vote is not None
            vote.feed(block)
            window += block
            if (
                vote.seen >= AUTO_WINDOW_MAX
                or parser.chunks >= AUTO_WINDOW_RECORDS
                or (vote.seen >= AUTO_WINDOW and any(vote.good.values()))
            ):
                decide(final=False)
        out.flush()
    if not total:
        raise UsageError("no hex bytes found in the input" + _word_dump_hint(parser))
    if decoder is None:
        decide(final=True)
    assert decoder is not None and profile is not None
    out.records(decoder.close(), profile)
    if not args.json:
        summary = f"{out.frames} frames, {out.good} good, {out.frames - out.good} with errors"
        if out.garbage:
            summary += f", {out.garbage} garbage bytes"
        if parser.skipped:
            summary += f"; {parser.skipped} non-hex lines skipped" + _word_dump_hint(parser)
        out.line(f"{BOLD}{summary}{RESET}" if out.colour else summary)
    out.flush()
    return 1 if out.failed or not out.frames else 0


def _word_dump_hint(parser: HexTextParser) -> str:
    if not parser.word_dump_lines:
        return ""
    return (f" ({parser.word_dump_lines} lines of 2-byte words in host order, as od and hexdump "
            "print by default: give od -t x1 or hexdump -C)")  # fmt: skip
