"""pcapng for Wireshark, written and read with `struct` (no dependency). Pure: records <-> bytes.

Link types (see docs/captures.md):
* Type I (serial frames): LINKTYPE_USER0 (147), one packet per frame, the frame bytes exactly as on
  the wire. One interface per direction, named after it (`ixl>atc`); each packet also carries the
  direction in an `opt_comment` and in `epb_flags` (outbound for the first direction seen, inbound
  for its reverse). In Wireshark map DLT_USER 0 to a dissector (Preferences > Protocols > DLT_USER).
* Type II (TCP): LINKTYPE_RAW (101), synthesised IPv4 + TCP packets (PSH|ACK, valid checksums and
  running SEQ/ACK numbers per direction), so Wireshark shows addresses, ports and follows the
  stream. Endpoint addresses are the real ones when the tap knows them, else 127.0.0.<k>:<20000+k>
  in order of first appearance. The direction is again in `opt_comment`.
Timestamps are microseconds since the epoch (if_tsresol = 6).
"""

from __future__ import annotations

import functools
import ipaddress
import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

from ktcs_bench.capture.records import CaptureRecord, reverse_direction, split_direction
from ktcs_bench.errors import UsageError

LINKTYPE_RAW = 101
LINKTYPE_USER0 = 147
LINK_TYPES = {"type1": LINKTYPE_USER0, "type2": LINKTYPE_RAW}
SNAPLEN = 262144

BT_SHB, BT_IDB, BT_EPB, BT_SPB = 0x0A0D0D0A, 0x00000001, 0x00000006, 0x00000003
BYTE_ORDER_MAGIC = 0x1A2B3C4D
OPT_ENDOFOPT, OPT_COMMENT = 0, 1
SHB_USERAPPL = 4
IF_NAME, IF_DESCRIPTION, IF_TSRESOL = 2, 3, 9
EPB_FLAGS = 2
FLAG_INBOUND, FLAG_OUTBOUND = 0b01, 0b10
TCP_PSH_ACK = 0x18
ISN = 1000  # initial TCP sequence number of each synthesised direction
_EPB_HEAD = struct.Struct("<IIIIIII")  # block type, length; interface, time, lengths
_TOTAL = struct.Struct("<I")


def _pad(data: bytes) -> bytes:
    return data + b"\0" * (-len(data) % 4)


def _option(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + _pad(value)


def _options(opts: list[tuple[int, bytes]]) -> bytes:
    if not opts:
        return b""
    return b"".join(_option(c, v) for c, v in opts) + struct.pack("<HH", OPT_ENDOFOPT, 0)


def _block(block_type: int, body: bytes) -> bytes:
    total = 12 + len(body)
    return struct.pack("<II", block_type, total) + body + struct.pack("<I", total)


def section_header(application: str = "ktcs-bench") -> bytes:
    body = struct.pack("<IHHq", BYTE_ORDER_MAGIC, 1, 0, -1)
    return _block(BT_SHB, body + _options([(SHB_USERAPPL, application.encode())]))


def interface_description(linktype: int, name: str, description: str = "") -> bytes:
    opts = [(IF_NAME, name.encode()), (IF_TSRESOL, bytes([6]))]
    if description:
        opts.append((IF_DESCRIPTION, description.encode()))
    return _block(BT_IDB, struct.pack("<HHI", linktype, 0, SNAPLEN) + _options(opts))


def enhanced_packet(
    interface: int, time: float, data: bytes, flags: int | None = None, comment: str | None = None
) -> bytes:
    us = max(0, round(time * 1_000_000))
    head = struct.pack("<IIIII", interface, us >> 32, us & 0xFFFFFFFF, len(data), len(data))
    opts: list[tuple[int, bytes]] = []
    if flags is not None:
        opts.append((EPB_FLAGS, struct.pack("<I", flags)))
    if comment:
        opts.append((OPT_COMMENT, comment.encode()))
    return _block(BT_EPB, head + _pad(data) + _options(opts))


def _checksum(data: bytes) -> int:
    """The Internet checksum (RFC 1071). The one's-complement sum of the 16-bit words is the
    data read as one big-endian number modulo 0xFFFF (2**16 = 1 modulo 0xFFFF), in C, save
    that a sum of words that are not all zero folds to 0xFFFF, never 0."""
    if len(data) % 2:
        data += b"\0"
    number = int.from_bytes(data, "big")
    total = number % 0xFFFF
    if not total and number:
        total = 0xFFFF
    return ~total & 0xFFFF


@functools.lru_cache(maxsize=256)
def _packed_ip(address: str) -> bytes:
    """A dotted IPv4 address as 4 bytes (a capture has a handful, for every packet)."""
    return ipaddress.IPv4Address(address).packed


def ipv4_tcp_packet(
    src: tuple[str, int], dst: tuple[str, int], seq: int, ack: int, payload: bytes, ident: int = 0
) -> bytes:
    """An IPv4 + TCP (PSH|ACK) packet carrying `payload`, with valid checksums."""
    s_ip = _packed_ip(src[0])
    d_ip = _packed_ip(dst[0])
    tcp = struct.pack("!HHIIBBHHH", src[1], dst[1], seq & 0xFFFFFFFF, ack & 0xFFFFFFFF,
                      5 << 4, TCP_PSH_ACK, 65535, 0, 0)  # fmt: skip
    pseudo = s_ip + d_ip + struct.pack("!BBH", 0, 6, len(tcp) + len(payload))
    csum = _checksum(pseudo + tcp + payload)
    tcp = tcp[:16] + struct.pack("!H", csum) + tcp[18:]
    total = 20 + len(tcp) + len(payload)
    ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, total, ident & 0xFFFF, 0x4000, 64, 6, 0, s_ip, d_ip)
    ip = ip[:10] + struct.pack("!H", _checksum(ip)) + ip[12:]
    return ip + tcp + payload


@dataclass
class _TcpState:
    next_seq: dict[str, int] = field(default_factory=dict)
    ident: int = 0


class PcapngEncoder:
    """Records in, pcapng bytes out. `link` is "type1" (serial frames) or "type2" (TCP)."""

    def __init__(
        self, link: str = "type1", endpoints: Mapping[str, tuple[str, int]] | None = None
    ) -> None:
        if link not in LINK_TYPES:
            raise UsageError(f"pcapng link must be one of {sorted(LINK_TYPES)}, not {link!r}")
        self.link = link
        self._interfaces: dict[str, int] = {}
        self._first: str | None = None
        self._endpoints: dict[str, tuple[str, int]] = dict(endpoints or {})
        self._tcp = _TcpState()
        self._started = False
        self._options: dict[tuple[int, str], bytes] = {}
        # a Type I direction once its interface is described: (interface, options of its packets)
        self._serial: dict[str, tuple[int, bytes]] = {}
        # a Type II direction: (source, destination, the other direction), until an endpoint moves
        self._routes: dict[str, tuple[tuple[str, int], tuple[str, int], str]] = {}

    def set_endpoint(self, name: str, host: str, port: int) -> None:
        """The real address of a Type II endpoint, for the packets that follow. An address the
        synthesised IPv4 packets cannot carry (IPv6, a host name) keeps the synthesised one."""
        try:
            ip = ipaddress.ip_address(host)
        except ValueError:
            return
        v4 = ip if isinstance(ip, ipaddress.IPv4Address) else ip.ipv4_mapped
        if v4 is not None and 0 <= port <= 0xFFFF:
            self._endpoints[name] = (str(v4), port)
            self._routes.clear()

    def start(self) -> bytes:
        self._started = True
        out = section_header()
        if self.link == "type2":
            self._interfaces["type2"] = 0
            out += interface_description(LINKTYPE_RAW, "type2", "ktcs Type II over TCP")
        return out

    def _endpoint(self, name: str) -> tuple[str, int]:
        if name not in self._endpoints:
            k = len(self._endpoints) + 1
            self._endpoints[name] = (f"127.0.0.{k}", 20000 + k)
        return self._endpoints[name]

    def encode(self, record: CaptureRecord) -> bytes:
        serial = self._serial.get(record.direction)
        if serial is not None:  # a Type I direction seen before: everything but the packet made
            time = record.time if record.time is not None else 0.0
            return self._block(serial[0], time, record.data, serial[1])
        out = b"" if self._started else self.start()
        time = record.time if record.time is not None else 0.0
        direction = record.direction
        if self._first is None:
            self._first = direction
        flags = FLAG_OUTBOUND if direction == self._first else FLAG_INBOUND
        if self.link == "type1":
            if direction not in self._interfaces:
                self._interfaces[direction] = len(self._interfaces)
                out += interface_description(
                    LINKTYPE_USER0, direction, f"ktcs Type I serial {direction}"
                )
            interface = self._interfaces[direction]
            self._serial[direction] = (interface, self._options_of(flags, direction))
            return out + self._packet(interface, time, record.data, flags, direction)
        route = self._routes.get(direction)
        if route is None:
            pair = split_direction(direction) or (direction, reverse_direction(direction))
            route = (self._endpoint(pair[0]), self._endpoint(pair[1]), reverse_direction(direction))
            self._routes[direction] = route
        src, dst, back = route
        seq = self._tcp.next_seq.get(direction, ISN)
        ack = self._tcp.next_seq.get(back, ISN)
        self._tcp.next_seq[direction] = seq + len(record.data)
        self._tcp.ident += 1
        packet = ipv4_tcp_packet(src, dst, seq, ack, record.data, self._tcp.ident)
        return out + self._packet(0, time, packet, flags, direction)

    def _packet(self, interface: int, time: float, data: bytes, flags: int, comment: str) -> bytes:
        """`enhanced_packet`, its options (the same for every packet of a direction) made once."""
        return self._block(interface, time, data, self._options_of(flags, comment))

    def _options_of(self, flags: int, comment: str) -> bytes:
        opts = self._options.get((flags, comment))
        if opts is None:
            listed = [(EPB_FLAGS, struct.pack("<I", flags))]
            if comment:
                listed.append((OPT_COMMENT, comment.encode()))
            opts = self._options[(flags, comment)] = _options(listed)
        return opts

    @staticmethod
    def _block(interface: int, time: float, data: bytes, opts: bytes) -> bytes:
        us = max(0, round(time * 1_000_000))
        n = len(data)
        pad = -n % 4
        total = 32 + n + pad + len(opts)
        return b"".join((
            _EPB_HEAD.pack(BT_EPB, total, interface, us >> 32, us & 0xFFFFFFFF, n, n),
            data, b"\0" * pad, opts, _TOTAL.pack(total),
        ))  # fmt: skip


# -- reading -------------------------------------------------------------------------------------


@dataclass
class _Interface:
    linktype: int
    name: str | None
    resolution: float


def _parse_options(data: bytes, endian: str) -> Iterator[tuple[int, bytes]]:
    pos = 0
    while pos + 4 <= len(data):
        code, length = struct.unpack_from(endian + "HH", data, pos)
        pos += 4
        if code == OPT_ENDOFOPT:
            return
        yield code, data[pos : pos + length]
        pos += length + (-length % 4)


def _tsresol(value: bytes) -> float:
    if not value:
        return 1e-6
    v = value[0]
    return 2.0 ** -(v & 0x7F) if v & 0x80 else 10.0**-v


def _tcp_payload(packet: bytes) -> bytes:
    if len(packet) < 20 or packet[0] >> 4 != 4 or packet[9] != 6:
        return packet
    ihl = (packet[0] & 0x0F) * 4
    total = struct.unpack_from("!H", packet, 2)[0]
    tcp = packet[ihl:total]
    if len(tcp) < 20:
        return b""
    return tcp[(tcp[12] >> 4) * 4 :]


def parse_pcapng(data: bytes) -> list[CaptureRecord]:
    """Packets of a pcapng file as records (TCP payloads for raw-IP/Ethernet, frames otherwise).

    The direction is the packet's comment, else its interface's name, else `if<N>`.
    """
    records: list[CaptureRecord] = []
    interfaces: list[_Interface] = []
    endian = "<"
    pos = 0
    while pos + 12 <= len(data):
        block_type = struct.unpack_from("<I", data, pos)[0]
        if block_type == BT_SHB:
            magic = data[pos + 8 : pos + 12]
            endian = "<" if magic == struct.pack("<I", BYTE_ORDER_MAGIC) else ">"
            interfaces = []
        block_type, total = struct.unpack_from(endian + "II", data, pos)
        if total < 12 or pos + total > len(data):
            raise UsageError(f"pcapng: bad block length {total} at byte {pos}")
        body = data[pos + 8 : pos + total - 4]
        pos += total
        if block_type == BT_IDB:
            linktype = struct.unpack_from(endian + "H", body, 0)[0]
            name, res = None, 1e-6
            for code, value in _parse_options(body[8:], endian):
                if code == IF_NAME:
                    name = value.decode(errors="replace")
                elif code == IF_TSRESOL:
                    res = _tsresol(value)
            interfaces.append(_Interface(linktype, name, res))
        elif block_type == BT_EPB:
            iface, hi, lo, caplen, _ = struct.unpack_from(endian + "IIIII", body, 0)
            if iface >= len(interfaces):
                raise UsageError(f"pcapng: packet on undeclared interface {iface}")
            it = interfaces[iface]
            packet = body[20 : 20 + caplen]
            comment = None
            for code, value in _parse_options(body[20 + caplen + (-caplen % 4) :], endian):
                if code == OPT_COMMENT:
                    comment = value.decode(errors="replace")
            if it.linktype == LINKTYPE_RAW:
                packet = _tcp_payload(packet)
            elif it.linktype == 1:  # Ethernet II carrying IPv4
                packet = _tcp_payload(packet[14:]) if packet[12:14] == b"\x08\x00" else packet
            if not packet:
                continue
            direction = comment or it.name or f"if{iface}"
            records.append(CaptureRecord(((hi << 32) | lo) * it.resolution, direction, packet))
    return records


def is_pcapng(head: bytes) -> bool:
    return head[:4] == struct.pack("<I", BT_SHB)
