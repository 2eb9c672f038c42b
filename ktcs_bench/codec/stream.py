"""The streaming decoder: bytes in any chunking -> frames, error frames and garbage, with offsets.

Framing is by LEN (no byte stuffing), so STX may occur inside DATA and inside garbage. The decoder
treats every STX as a candidate and resynchronises as SPEC §3.1 says:

* a complete candidate that fails a check is one error frame, its DATA whole, when its LEN is
  borne out by its own bytes -- the ETX sits where LEN says the frame ends (or, for an ETX error,
  the CRC over LEN checks) -- unless a valid frame lies wholly inside it, in which case it was a
  false STX and its bytes up to that frame are garbage. One corrupted frame is one error record
  (one NAK), whatever STX bytes its DATA or CRC holds;
* a failed candidate whose LEN nothing bears out (no ETX in the profile, or the wrong byte there)
  is an error frame up to the first inner STX that could begin a real frame -- one whose LEN is in
  range and announces a frame ending past the candidate -- where decoding resumes; inner STX bytes
  whose frames are ruled out by the candidate's own bytes do not cut it;
* only the candidate's own bytes decide, so the verdict does not depend on how the input was
  chunked, and it comes as soon as the candidate is complete (a link NAKs at once);
* while a candidate waits for more bytes, any complete valid frame that starts after it wins, so a
  false STX in garbage announcing a long frame never swallows the good frame behind it;
* after an error frame, candidates inside the failed frame's extent that fail too are garbage, not
  further errors;
* memory is bounded by the profile's largest frame: LEN is checked against `max_len` before it is
  used, and nothing is ever allocated from it.

The price of the first rule: a false STX in garbage whose LEN-implied end happens to hold the ETX
byte (1 in 256) is taken for a corrupted frame, and a good frame starting inside it and ending past
it is lost with it (a link recovers it by its retransmission).

`close()` reports a frame still incomplete at the end of input as "truncated"; `abandon()` does the
same mid-stream, for a receiver whose ΔR timer expired.
"""

from __future__ import annotations

import struct

from ktcs_bench.codec.frame import Frame, Garbage, Record
from ktcs_bench.codec.profile import FrameProfile

# Garbage with no STX in it is held back (to merge byte-at-a-time input into one span) up to this.
GARBAGE_HOLD = 4096


class StreamDecoder:
    """Feed bytes with `feed()`; get records in stream order. Offsets count from `offset`."""

    def __init__(self, profile: FrameProfile, offset: int = 0) -> None:
        self.profile = profile
        p = profile
        self._buf = bytearray()
        self._base = offset  # stream offset of _buf[0]
        self._stx = p.stx
        self._etx = p.etx
        self._hsize = p.header_size
        self._header = p.header_struct()
        names = [n for n, _ in p.header]
        self._i_len = names.index("len")
        self._i_seq = names.index("seq")
        self._i_op = names.index("op")
        self._i_sub = names.index("sub") if "sub" in names else None
        self._fixed = p.fixed_counted
        self._max_len = p.max_len
        self._trailer = p.trailer_size
        self._crc = p.crc_function()
        self._kernel = p.crc_spec.kernel()
        order = "<" if p.little else ">"
        tail_fmt = order + {1: "B", 2: "H", 4: "I"}[p.crc_size]
        tail_fmt += f"{p.crc_pad}s" if p.crc_pad else ""
        tail_fmt += "" if p.etx is None else "B"
        self._tail = struct.Struct(tail_fmt)  # CRC, pad, ETX in one unpack on the hot path
        self._tail_ok = ((bytes(p.crc_pad),) if p.crc_pad else ()) + (
            () if p.etx is None else (p.etx,)
        )
        self._crc_size = p.crc_size
        self._crc_pad = p.crc_pad
        self._crc_little = p.little
        self._crc_from = p.offset_of(p.crc_first)[0]
        self._crc_to_header = None if p.crc_last == "data" else sum(p.offset_of(p.crc_last))
        # a CRC that checks over LEN bears LEN out (for a frame whose only fault is its ETX)
        self._crc_covers_len = p.crc_first in ("stx", "len")
        self._held = 0  # bytes at the start of _buf already known to be garbage, not yet reported
        self._pending = False  # _buf[_held] is an STX whose frame is still incomplete
        self._hot = (
            self._stx,
            self._hsize,
            self._header.unpack_from,
            self._i_len,
            self._i_seq,
            self._i_op,
            self._i_sub,
            self._fixed,
            self._max_len,
            self._trailer,
            *self._kernel,
            self._crc_from,
            self._crc_to_header,
            self._tail.unpack_from,
            self._tail_ok,
        )  # fmt: skip -- everything the hot loop needs, unpacked into locals in one step
        self._suspect_until = 0  # absolute offset: failures before it are garbage
        self._probe_for = -1  # absolute offset of the pending candidate the probe state is for
        self._probe_next = 0  # absolute offset from which candidates are not yet classified
        self._probe_wait: list[tuple[int, int]] = []  # (candidate, absolute end) incomplete
        # absolute offset at which the pending candidate completes, while everything after its
        # STX is classified and no inner candidate waits (0: not known). Until then bytes with
        # no STX in them change nothing but the buffer: `feed` takes them without a pass (a
        # frame arriving in pieces on a line is decoded once, when its last piece comes)
        self._need = 0

    # -- public API --------------------------------------------------------------------------
    @property
    def pending(self) -> bool:
        """True while a frame has begun (STX seen) but is not yet complete."""
        return self._pending

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Record]:
        buf = self._buf
        n0 = len(buf)
        buf += data
        n = len(buf)
        stx = self._stx
        if self._need:  # a frame's next piece: what `_process` would conclude, without a pass
            if self._base + n < self._need and buf.find(stx, n0) < 0:
                self._probe_next = self._base + n
                return []
            if self._base + n == self._need and not self._held:
                last = self._last_piece()  # its last piece, the frame alone in the buffer
                if last is not None:
                    return last
        elif not n0 and n >= self._hsize and buf[0] == stx:  # on an empty buffer, a header
            length = self._header.unpack_from(buf, 1)[self._i_len]
            data_len = length - self._fixed
            total = self._hsize + data_len + self._trailer
            if 0 <= data_len and length <= self._max_len:
                if total == n:  # a whole frame and nothing else
                    whole = self._last_piece()
                    if whole is not None:
                        return whole
                elif total > n and buf.find(stx, 1) < 0:  # a frame's first piece: pending
                    base = self._base
                    self._pending = True
                    self._probe_for, self._probe_next, self._probe_wait = base, base + n, []
                    self._need = base + total
                    return []
        return self._process(final=False)

    def close(self) -> list[Record]:
        """End of input: report what is left (a truncated frame, trailing garbage)."""
        out = self._process(final=False)
        self._need = 0
        j = self._pending_at()
        buf = self._buf
        if j is not None:
            if j:
                out.append(Garbage(self._base, bytes(buf[:j])))
            out.append(self._truncated(j, len(buf)))
        elif buf:
            out.append(Garbage(self._base, bytes(buf)))
        self._consume(len(buf))
        self._held, self._pending = 0, False
        return out

    def abandon(self) -> list[Record]:
        """Give up on the pending frame (ΔR expired): report it truncated, resume after its STX."""
        self._need = 0
        j = self._pending_at()
        if j is None:
            return []
        out: list[Record] = []
        if j:
            out.append(Garbage(self._base, bytes(self._buf[:j])))
        nxt = self._buf.find(self._stx, j + 1)
        end = len(self._buf) if nxt < 0 else nxt
        out.append(self._truncated(j, end))
        self._consume(end)
        self._held, self._pending = 0, False
        out.extend(self._process(final=False))
        return out

    # -- internals ---------------------------------------------------------------------------
    def _last_piece(self) -> list[Record] | None:
        """The buffer holds exactly one frame, its LEN in range (the pending frame's last piece
        has come, or a whole frame came to an empty buffer): if its checks pass, it is the one
        record `_process` would give (its fast path, at offset 0), and the buffer empties; None
        (nothing changed) if not."""
        (stx, hs, unpack, i_len, i_seq, i_op, i_sub, fixed, max_len, trailer, crc_fn, crc_init,
         crc_table, crc_xor, crc_from, crc_to, tail_unpack, tail_ok) = self._hot  # fmt: skip
        raw = bytes(self._buf)
        h = unpack(raw, 1)
        at = hs + h[i_len] - fixed
        calc = crc_xor ^ crc_fn(raw[crc_from : at if crc_to is None else crc_to], crc_init,
                                crc_table)  # fmt: skip
        tail = tail_unpack(raw, at)
        if tail[0] != calc or tail[1:] != tail_ok:
            return None
        self._need = 0
        self._pending = False
        self._consume(len(raw))
        # built in C (`tuple.__new__`), as `_process` builds its frames
        fields = (self._base - len(raw), raw, h[i_seq], h[i_op],
                  None if i_sub is None else h[i_sub], hs, at, calc, calc, None)  # fmt: skip
        return [tuple.__new__(Frame, fields)]

    def _pending_at(self) -> int | None:
        return self._held if self._pending else None

    def _consume(self, n: int) -> None:
        if n:
            del self._buf[:n]
            self._base += n
            self._held = max(0, self._held - n)

    def _truncated(self, j: int, end: int) -> Frame:
        raw = bytes(self._buf[j:end])
        seq = op = sub = None
        if len(raw) >= self._hsize:
            h = self._header.unpack_from(raw, 1)
            seq, op = h[self._i_seq], h[self._i_op]
            sub = None if self._i_sub is None else h[self._i_sub]
        start = min(self._hsize, len(raw))
        return Frame(self._base + j, raw, seq, op, sub, start, len(raw), None, None,
                     "truncated")  # fmt: skip

    def _check(
        self, buf: bytearray, j: int, total: int, data_len: int
    ) -> tuple[int, int, str | None]:
        """(crc in packet, crc computed, error) for a complete candidate at j."""
        hs = self._hsize
        c_end = j + hs + data_len if self._crc_to_header is None else j + self._crc_to_header
        calc = self._crc(memoryview(buf)[j + self._crc_from : c_end])
        at = j + hs + data_len
        packet = int.from_bytes(
            buf[at : at + self._crc_size], "little" if self._crc_little else "big"
        )
        pad_end = at + self._crc_size + self._crc_pad
        if packet != calc or (self._crc_pad and any(buf[at + self._crc_size : pad_end])):
            return packet, calc, "crc"
        if self._etx is not None and buf[j + total - 1] != self._etx:
            return packet, calc, "etx"
        return packet, calc, None

    def _valid_at(self, buf: bytearray, q: int, n: int) -> bool | None:
        """Whether a complete valid frame starts at q: True/False, None if not yet decidable."""
        if n - q < self._hsize:
            return None
        length = self._header.unpack_from(buf, q + 1)[self._i_len]
        data_len = length - self._fixed
        if data_len < 0 or length > self._max_len:
            return False
        total = self._hsize + data_len + self._trailer
        if n - q < total:
            return None
        return self._check(buf, q, total, data_len)[2] is None

    def _inner_frame(self, buf: bytearray, j: int, end: int) -> int | None:
        """First q in (j, end) where a valid frame lies wholly inside the failed candidate [j, end).

        Only the candidate's own bytes decide, so the verdict is the same however the input was
        chunked, and it is reached as soon as the candidate is complete (a link NAKs at once).
        """
        q = j
        while True:
            q = buf.find(self._stx, q + 1, end)
            if q < 0:
                return None
            if self._valid_at(buf, q, end):
                return q

    def _len_borne_out(self, buf: bytearray, j: int, total: int, error: str) -> bool:
        """Whether the failed candidate's own bytes confirm where its LEN says it ends."""
        if error == "etx":
            return self._crc_covers_len
        return self._etx is not None and buf[j + total - 1] == self._etx

    def _cut(self, buf: bytearray, j: int, end: int) -> int:
        """Where an error frame [j, end) whose LEN nothing bears out stops: at the first inner STX
        that could begin a real frame (its header runs past `end`, or its LEN is in range and
        announces a frame ending past `end`), else at `end`. Inner candidates lying wholly inside
        were all found invalid by `_inner_frame`, so they cannot be frames."""
        hs, unpack, i_len = self._hsize, self._header.unpack_from, self._i_len
        q = j
        while True:
            q = buf.find(self._stx, q + 1, end)
            if q < 0:
                return end
            if end - q < hs:
                return q
            length = unpack(buf, q + 1)[i_len]
            data_len = length - self._fixed
            in_range = 0 <= data_len and length <= self._max_len
            if in_range and q + hs + data_len + self._trailer > end:
                return q

    def _probe(self, buf: bytearray, j: int, limit: int) -> int | None:
        """First q in (j, limit) where a complete valid frame starts, remembering what was ruled out."""
        base = self._base
        n = len(buf)
        if self._probe_for != base + j:
            self._probe_for = base + j
            self._probe_next = base + j + 1
            self._probe_wait = []
        still: list[tuple[int, int]] = []
        found: int | None = None
        for q_abs, end_abs in self._probe_wait:
            if found is None and end_abs <= base + n:
                if self._valid_at(buf, q_abs - base, n):
                    found = q_abs - base
            else:
                still.append((q_abs, end_abs))
        self._probe_wait = still
        if found is not None and found < limit:
            return found
        q = self._probe_next - base
        while True:
            q = buf.find(self._stx, q, min(limit, n))
            if q < 0:
                self._probe_next = base + min(limit, n)
                return None
            verdict = self._valid_at(buf, q, n)
            if verdict:
                return q
            if verdict is None:
                if n - q < self._hsize:
                    self._probe_next = base + q  # header incomplete: look again next time
                    return None
                length = self._header.unpack_from(buf, q + 1)[self._i_len]
                end = q + self._hsize + length - self._fixed + self._trailer
                self._probe_wait.append((base + q, base + end))
            q += 1

    def _process(self, final: bool) -> list[Record]:
        """Decode what the buffer holds. The loop body is the fast path -- a complete frame whose
        checks pass, at the read position; everything else goes to `_resolve`."""
        self._need = 0
        out: list[Record] = []
        append = out.append
        buf = self._buf
        n = len(buf)
        i = self._held
        g = 0 if i else -1  # start of the current garbage run, -1 for none
        pending = False
        base = self._base
        (stx, hs, unpack, i_len, i_seq, i_op, i_sub, fixed, max_len, trailer, crc_fn, crc_init,
         crc_table, crc_xor, crc_from, crc_to, tail_unpack, tail_ok) = self._hot  # fmt: skip
        find = buf.find
        new = tuple.__new__
        mv = memoryview(buf)
        try:
            while i < n:
                if buf[i] != stx:
                    j = find(stx, i)
                    if g < 0:
                        g = i
                    if j < 0:
                        i = n
                        break
                    i = j
                if n - i < hs:
                    pending = True
                    break
                h = unpack(buf, i + 1)
                data_len = h[i_len] - fixed
                at = i + hs + data_len
                end = at + trailer
                if 0 <= data_len and h[i_len] <= max_len and end <= n:
                    calc = crc_xor ^ crc_fn(
                        mv[i + crc_from : at if crc_to is None else i + crc_to], crc_init, crc_table
                    )
                    tail = tail_unpack(buf, at)
                    if tail[0] == calc and tail[1:] == tail_ok:
                        if g >= 0:
                            append(Garbage(base + g, mv[g:i].tobytes()))
                            g = -1
                        append(
                            new(Frame, (base + i, mv[i:end].tobytes(), h[i_seq], h[i_op],
                                        None if i_sub is None else h[i_sub], hs, hs + data_len,
                                        calc, calc, None))
                        )  # fmt: skip
                        i = end
                        continue
                i, g, pending = self._resolve(buf, mv, i, g, h, out)
                if pending:
                    break
            # i is where unconsumed input starts (a pending candidate, or n). Garbage before it is
            # held back, so that how the input was chunked never changes how garbage is reported.
            if g >= 0 and (i - g >= GARBAGE_HOLD or final):
                append(Garbage(base + g, mv[g:i].tobytes()))
                g = -1
        finally:
            mv.release()
        keep_from = g if g >= 0 else i
        self._pending = pending
        self._consume(keep_from)
        self._held = i - keep_from
        return out

    def _resolve(
        self, buf: bytearray, mv: memoryview, j: int, g: int, h: tuple[int, ...], out: list[Record]
    ) -> tuple[int, int, bool]:
        """The slow path for the candidate at j: incomplete, out of range, or failing a check.
        Returns (next read position, garbage-run start, pending)."""
        base, hs, n = self._base, self._hsize, len(buf)
        length = h[self._i_len]
        data_len = length - self._fixed
        packet: int | None = None
        calc: int | None = None
        if data_len < 0 or length > self._max_len:
            error: str | None = "length"
            total = hs
        else:
            total = hs + data_len + self._trailer
            if n - j < total:
                q = self._probe(buf, j, n)
                if q is None:
                    if not self._probe_wait and self._probe_next == base + n:
                        self._need = base + j + total  # see `feed`
                    return j, g, True
                return q, (j if g < 0 else g), False
            packet, calc, error = self._check(buf, j, total, data_len)
        if error is None:  # cannot happen: the fast path takes good frames
            raise AssertionError("slow path given a good frame")
        q = self._inner_frame(buf, j, j + total) if error != "length" else None
        if q is not None or base + j < self._suspect_until:
            return (j + 1 if q is None else q), (j if g < 0 else g), False
        if error == "length":
            nxt = buf.find(self._stx, j + 1, j + total)
            end = j + total if nxt < 0 else nxt
        elif self._len_borne_out(buf, j, total, error):
            end = j + total
        else:
            end = self._cut(buf, j, j + total)
        self._suspect_until = base + j + total
        if g >= 0:
            out.append(Garbage(base + g, mv[g:j].tobytes()))
        # DATA as far as this record holds it: a candidate cut at an STX inside it is shorter
        size = end - j
        out.append(
            Frame(base + j, mv[j:end].tobytes(), h[self._i_seq], h[self._i_op],
                  None if self._i_sub is None else h[self._i_sub], min(hs, size),
                  min(hs + max(data_len, 0), size), packet, calc, error)
        )  # fmt: skip
        return end, -1, False
