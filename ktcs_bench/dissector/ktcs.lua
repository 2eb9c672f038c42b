-- ktcs.lua: a Wireshark dissector for the kTCS wire protocols of ktcs-bench.
--
--   ktcs1  Type I  (vital serial link: IXL <-> ATC, IXL <-> trackside I/O), in LINKTYPE_USER0
--                  captures: one direction per interface, any packetisation of the byte stream;
--   ktcs2  Type II (CTC <-> IXL over TCP): Decode As on a TCP port, a heuristic TCP dissector,
--                  and the TCP ports of the preference ktcs2.tcp_ports; TCP reassembly.
--
-- Written by `ktcs-bench dissector` from the bench's wire profiles (protocols/*.yaml). The KTCS
-- table below is the generated data; the code after it reads nothing else, so a vendor's profile
-- added as YAML is dissected with no change here. Regenerate rather than edit.
--
-- Each direction's bytes are framed as the bench's stream decoder frames them
-- (ktcs_bench/codec/stream.py, SPEC §3.1): several frames in one packet, a frame split over
-- packets, garbage between frames, a false STX in garbage, one record per corrupted frame. A
-- record is shown in the packet that holds its last byte; a frame still incomplete when the
-- capture ends is reported truncated. Both need the whole capture: use `tshark -2` (Wireshark
-- itself always has it).
--
--   tshark -2 -X lua_script:ktcs.lua -r capture.pcapng -V
--   tshark -2 -X lua_script:ktcs.lua -o ktcs1.profile:ktcs-type1-fig7 -r fig7.pcapng
--   tshark -2 -X lua_script:ktcs.lua -d tcp.port==5020,ktcs2 -r type2.pcapng

-- @KTCS_DATA@

---------------------------------------------------------------------------------------------
-- Bits and bytes. Lua 5.2 has bit32; Wireshark builds on later Lua bundle LuaBitOp's `bit`,
-- whose results are signed: u32() folds them back.
---------------------------------------------------------------------------------------------
local bitlib = bit32 or bit
local function u32(x)
    if x < 0 then return x + 4294967296 end
    return x
end
local function band(a, b) return u32(bitlib.band(a, b)) end
local function bxor(a, b) return u32(bitlib.bxor(a, b)) end
local function rshift(a, n) return u32(bitlib.rshift(a, n)) end
local function lshift(a, n) return u32(bitlib.lshift(a, n)) end

local sbyte, ssub, sfind, sfmt = string.byte, string.sub, string.find, string.format

-- Offsets are 0-based, as in the Python decoder.
local function byte_at(buf, i) return sbyte(buf, i + 1) end

local function uint_at(buf, i, size, little)
    local v = 0
    if little then
        for k = size - 1, 0, -1 do v = v * 256 + sbyte(buf, i + k + 1) end
    else
        for k = 0, size - 1 do v = v * 256 + sbyte(buf, i + k + 1) end
    end
    return v
end

-- First index in [from, to) holding the byte `ch` (a one-character string), or nil.
local function find_char(buf, ch, from, to)
    if from >= to then return nil end
    local k = sfind(buf, ch, from + 1, true)
    if k == nil or k - 1 >= to then return nil end
    return k - 1
end

---------------------------------------------------------------------------------------------
-- CRC: table-driven, the table generated from the profile's poly/reflect parameters. As crcmod
-- (which the Python codecs use): the register starts at init ^ xor_out and ends ^ xor_out.
---------------------------------------------------------------------------------------------
local function crc_of(crc, buf, from, to)
    local t, xo = crc.table, crc.xor_out
    local reg = bxor(crc.init, xo)
    if crc.reflect then
        for k = from + 1, to do
            reg = bxor(rshift(reg, 8), t[band(bxor(reg, sbyte(buf, k)), 255) + 1])
        end
    else
        local shift, mask = crc.width - 8, crc.mask
        for k = from + 1, to do
            reg = bxor(band(lshift(reg, 8), mask), t[band(bxor(rshift(reg, shift), sbyte(buf, k)), 255) + 1])
        end
    end
    return bxor(reg, xo)
end

---------------------------------------------------------------------------------------------
-- One codec per profile: the derived layout (computed by the generator from the same
-- FrameProfile objects the Python codecs are built from) plus a few lookups.
---------------------------------------------------------------------------------------------
local function new_codec(p)
    local c = {
        p = p, name = p.name, stx = p.stx, stx_char = string.char(p.stx), etx = p.etx,
        little = p.little, hs = p.header_size, fixed = p.fixed_counted, max_len = p.max_len,
        trailer = p.trailer_size, crc = p.crc, field = {},
    }
    for _, h in ipairs(p.header) do c.field[h.name] = h end
    c.len_off, c.len_size = c.field.len.offset, c.field.len.size
    return c
end

local function header_at(c, buf, i)
    local h = {}
    for _, f in ipairs(c.p.header) do h[f.name] = uint_at(buf, i + f.offset, f.size, c.little) end
    return h
end

-- (crc in packet, crc computed, error) of a complete candidate at j: error nil, "crc" or "etx".
local function check(c, buf, j, total, data_len)
    local cr = c.crc
    local c_end = cr.to_header and (j + cr.to_header) or (j + c.hs + data_len)
    local calc = crc_of(cr, buf, j + cr.from, c_end)
    local at = j + c.hs + data_len
    local packet = uint_at(buf, at, cr.size, c.little)
    if packet ~= calc then return packet, calc, "crc" end
    for k = at + cr.size, at + cr.size + cr.pad - 1 do
        if byte_at(buf, k) ~= 0 then return packet, calc, "crc" end
    end
    if c.etx and byte_at(buf, j + total - 1) ~= c.etx then return packet, calc, "etx" end
    return packet, calc, nil
end

-- Whether a complete valid frame starts at q within buf[q, n): true/false, nil if undecidable.
local function valid_at(c, buf, q, n)
    if n - q < c.hs then return nil end
    local len = uint_at(buf, q + c.len_off, c.len_size, c.little)
    local data_len = len - c.fixed
    if data_len < 0 or len > c.max_len then return false end
    local total = c.hs + data_len + c.trailer
    if n - q < total then return nil end
    local _, _, err = check(c, buf, q, total, data_len)
    return err == nil
end

---------------------------------------------------------------------------------------------
-- The stream decoder (ktcs_bench/codec/stream.py, rule for rule). Records:
--   {kind="frame", start, raw, len, seq, op, sub, data_start, data_end, crc_packet, crc_calc, err}
--   {kind="garbage", start, raw}
-- `start` is the record's offset in its direction's byte stream.
---------------------------------------------------------------------------------------------
local function garbage_rec(base, buf, a, b)
    return { kind = "garbage", start = base + a, raw = ssub(buf, a + 1, b) }
end

local function frame_rec(base, buf, a, b, h, ds, de, packet, calc, err)
    return {
        kind = "frame", start = base + a, raw = ssub(buf, a + 1, b), len = h.len, seq = h.seq,
        op = h.op, sub = h.sub, data_start = ds, data_end = de, crc_packet = packet,
        crc_calc = calc, err = err,
    }
end

local function truncated_rec(c, base, buf, j, n)
    local size = n - j
    local h = {}
    if size >= c.hs then h = header_at(c, buf, j) end
    return frame_rec(base, buf, j, n, h, math.min(c.hs, size), size, nil, nil, "truncated")
end

-- The first q in (j, n) where a complete valid frame starts (a false STX waiting for more bytes
-- never swallows the good frame behind it).
local function probe(c, buf, j, n)
    local q = j
    while true do
        q = find_char(buf, c.stx_char, q + 1, n)
        if q == nil then return nil end
        local v = valid_at(c, buf, q, n)
        if v == true then return q end
        if v == nil and n - q < c.hs then return nil end
    end
end

-- The first q in (j, stop) where a valid frame lies wholly inside the failed candidate.
local function inner_frame(c, buf, j, stop)
    local q = j
    while true do
        q = find_char(buf, c.stx_char, q + 1, stop)
        if q == nil then return nil end
        if valid_at(c, buf, q, stop) == true then return q end
    end
end

-- Whether a failed candidate's own bytes confirm where its LEN says it ends: the ETX there, or
-- (for an ETX error) a CRC that checks over LEN. Such a candidate is one error record, whole.
local function len_borne_out(c, buf, j, total, err)
    if err == "etx" then return c.crc.first == "stx" or c.crc.first == "len" end
    return c.etx ~= nil and byte_at(buf, j + total - 1) == c.etx
end

-- Where an error frame [j, stop) whose LEN nothing bears out ends: at the first inner STX that
-- could begin a real frame (its header runs past `stop`, or its LEN is in range and announces a
-- frame ending past `stop`), else at `stop`.
local function cut(c, buf, j, stop)
    local q = j
    while true do
        q = find_char(buf, c.stx_char, q + 1, stop)
        if q == nil then return stop end
        if stop - q < c.hs then return q end
        local len = uint_at(buf, q + c.len_off, c.len_size, c.little)
        local data_len = len - c.fixed
        if data_len >= 0 and len <= c.max_len and q + c.hs + data_len + c.trailer > stop then
            return q
        end
    end
end

-- The slow path for the candidate at j. Returns (next position, garbage-run start, pending).
local function resolve(c, buf, base, st, j, g, h, out)
    local n, hs = #buf, c.hs
    local length = h.len
    local data_len = length - c.fixed
    local packet, calc, err, total
    if data_len < 0 or length > c.max_len then
        err, total = "length", hs
    else
        total = hs + data_len + c.trailer
        if n - j < total then
            local q = probe(c, buf, j, n)
            if q == nil then return j, g, true end
            return q, (g or j), false
        end
        packet, calc, err = check(c, buf, j, total, data_len)
    end
    local q = nil
    if err ~= "length" then q = inner_frame(c, buf, j, j + total) end
    if q ~= nil or base + j < st.suspect_until then
        return (q or j + 1), (g or j), false
    end
    local stop
    if err == "length" then
        stop = find_char(buf, c.stx_char, j + 1, j + total) or (j + total)
    elseif len_borne_out(c, buf, j, total, err) then
        stop = j + total
    else
        stop = cut(c, buf, j, j + total)
    end
    st.suspect_until = base + j + total
    if g then out[#out + 1] = garbage_rec(base, buf, g, j) end
    local size = stop - j
    out[#out + 1] = frame_rec(base, buf, j, stop, h, math.min(hs, size),
        math.min(hs + math.max(data_len, 0), size), packet, calc, err)
    return stop, nil, false
end

-- Decode buf (the unconsumed bytes of one direction; buf[0] is at stream offset `base`).
-- Returns records, keep (bytes of buf now consumed) and pend (index of an incomplete candidate,
-- or nil). st.suspect_until persists between calls.
local function decode(c, buf, base, st)
    local out, n, i, g, pend = {}, #buf, 0, nil, nil
    while i < n do
        local at_stx = true
        if byte_at(buf, i) ~= c.stx then
            local j = find_char(buf, c.stx_char, i, n)
            if g == nil then g = i end
            if j == nil then
                i = n
                at_stx = false
            else
                i = j
            end
        end
        if not at_stx then break end
        if n - i < c.hs then
            pend = i
            break
        end
        local h = header_at(c, buf, i)
        local data_len = h.len - c.fixed
        local total = c.hs + data_len + c.trailer
        local good = false
        if data_len >= 0 and h.len <= c.max_len and i + total <= n then
            local packet, calc, err = check(c, buf, i, total, data_len)
            if err == nil then
                if g then
                    out[#out + 1] = garbage_rec(base, buf, g, i)
                    g = nil
                end
                out[#out + 1] = frame_rec(base, buf, i, i + total, h, c.hs, c.hs + data_len, packet, calc, nil)
                i = i + total
                good = true
            end
        end
        if not good then
            local pending
            i, g, pending = resolve(c, buf, base, st, i, g, h, out)
            if pending then
                pend = i
                break
            end
        end
    end
    if g and i - g >= KTCS.garbage_hold then
        out[#out + 1] = garbage_rec(base, buf, g, i)
        g = nil
    end
    return out, (g or i), pend
end

-- End of input: what is left (garbage before a pending candidate, the candidate truncated).
local function close_records(c, buf, base, pend)
    local out, n = {}, #buf
    if pend then
        if pend > 0 then out[1] = garbage_rec(base, buf, 0, pend) end
        out[#out + 1] = truncated_rec(c, base, buf, pend, n)
    elseif n > 0 then
        out[1] = garbage_rec(base, buf, 0, n)
    end
    return out
end

---------------------------------------------------------------------------------------------
-- Payloads (ktcs_bench/codec/opcodes.py Opcode.parse): fixed fields, then items or statuses.
---------------------------------------------------------------------------------------------
local function parse_payload(c, opc, data)
    local fixed = opc.fixed_size
    if #data < fixed then
        return nil, sfmt("%s: DATA has %d bytes, needs %d", opc.name, #data, fixed)
    end
    local res, off = { fields = {} }, 0
    for _, f in ipairs(opc.fields) do
        res.fields[#res.fields + 1] = { spec = f, offset = off, value = uint_at(data, off, f.size, c.little) }
        off = off + f.size
    end
    local rest = #data - fixed
    if opc.items then
        if rest % opc.item_size ~= 0 then
            return nil, sfmt("%s: %d item bytes is not a multiple of %d", opc.name, rest, opc.item_size)
        end
        res.items = {}
        while off < #data do
            local item = { offset = off, values = {} }
            for _, f in ipairs(opc.items) do
                item.values[#item.values + 1] = { spec = f, offset = off, value = uint_at(data, off, f.size, c.little) }
                off = off + f.size
            end
            res.items[#res.items + 1] = item
        end
    elseif opc.statuses then
        res.statuses = { offset = off, count = rest }
    elseif rest > 0 then
        return nil, sfmt("%s: %d unexpected bytes after the payload", opc.name, rest)
    end
    return res
end

---------------------------------------------------------------------------------------------
-- Protocols, fields, experts, preferences: one set per protocol, made from every profile of it.
---------------------------------------------------------------------------------------------
local function ident(s) return (s:lower():gsub("[^%w]+", "_")) end

local UINT = { [1] = ProtoField.uint8, [2] = ProtoField.uint16, [3] = ProtoField.uint24, [4] = ProtoField.uint32 }
local function uint_field(abbr, label, size, display)
    return UINT[size or 4](abbr, label, display or base.DEC)
end

local function code_name(number)
    local chart = KTCS.chart
    return chart and chart.codes[number]
end

local function new_proto(protocol, short, title)
    local P = { protocol = protocol, short = short, title = title, profiles = {}, names = {} }
    for _, name in ipairs(KTCS.order) do
        local p = KTCS.profiles[name]
        if p.protocol == protocol then
            P.profiles[#P.profiles + 1] = p
            P.names[#P.names + 1] = name
        end
    end
    P.proto = Proto(short, title)
    local F, x = {}, short .. "."
    -- header fields sized by the widest profile of this protocol
    local width = { len = 1, seq = 1, op = 1, sub = 1, crc = 1 }
    local payload_sizes, item_sizes = {}, {}
    for _, p in ipairs(P.profiles) do
        for _, h in ipairs(p.header) do width[h.name] = math.max(width[h.name], h.size) end
        width.crc = math.max(width.crc, p.crc.size)
        for _, opc in pairs(p.opcodes) do
            for _, f in ipairs(opc.fields) do
                local abbr = x .. ident(opc.name) .. "." .. ident(f.name)
                payload_sizes[abbr] = math.max(payload_sizes[abbr] or 1, f.size)
            end
            for _, f in ipairs(opc.items or {}) do
                item_sizes[f.name] = math.max(item_sizes[f.name] or 1, f.size)
            end
        end
    end
    F.stx = ProtoField.uint8(x .. "stx", "STX", base.HEX)
    F.len = uint_field(x .. "len", "Length", width.len, base.DEC)
    F.seq = uint_field(x .. "seq", "Sequence", width.seq, base.DEC_HEX)
    F.op = uint_field(x .. "op", "Opcode", width.op, base.HEX)
    F.op_name = ProtoField.string(x .. "op_name", "Opcode name")
    F.sub = uint_field(x .. "sub", "Sub-opcode", width.sub, base.DEC)
    F.sub_name = ProtoField.string(x .. "sub_name", "Sub-opcode name")
    F.data = ProtoField.bytes(x .. "data", "Data")
    F.crc = uint_field(x .. "crc", "CRC", width.crc, base.HEX)
    F.crc_calc = uint_field(x .. "crc_calc", "CRC computed", width.crc, base.HEX)
    F.crc_ok = ProtoField.bool(x .. "crc_ok", "CRC OK")
    F.crc_pad = ProtoField.bytes(x .. "crc_pad", "CRC padding")
    F.etx = ProtoField.uint8(x .. "etx", "ETX", base.HEX)
    F.error = ProtoField.string(x .. "error", "Error")
    F.profile = ProtoField.string(x .. "profile", "Profile")
    F.offset = ProtoField.uint32(x .. "offset", "Stream offset", base.DEC)
    F.garbage = ProtoField.bytes(x .. "garbage", "Garbage")
    F.items = ProtoField.uint32(x .. "items", "Items", base.DEC)
    F.item = ProtoField.none(x .. "item", "Item")
    F.status = ProtoField.uint8(x .. "status", "Status", base.DEC)
    F.first_in = ProtoField.framenum(x .. "first_in", "Begins in frame", base.NONE)
    F.shown_in = ProtoField.framenum(x .. "shown_in", "Bytes of the record shown in frame", base.NONE)
    F.ack_to = ProtoField.framenum(x .. "arq.ack_to", "ACK of the frame in", base.NONE, frametype and frametype.ACK)
    F.acked_in = ProtoField.framenum(x .. "arq.acked_in", "ACKed in frame", base.NONE)
    F.nak_to = ProtoField.framenum(x .. "arq.nak_to", "NAK of the frame in", base.NONE)
    F.naked_in = ProtoField.framenum(x .. "arq.naked_in", "NAKed in frame", base.NONE)
    F.retrans_of = ProtoField.framenum(x .. "arq.retransmission_of", "Retransmission of the frame in", base.NONE)
    F.transmission = ProtoField.uint8(x .. "arq.transmission", "Transmission", base.DEC)
    F.payload, F.item_f = {}, {}
    for abbr, size in pairs(payload_sizes) do
        F.payload[abbr] = uint_field(abbr, abbr:match("[^.]+$"), size, base.DEC)
    end
    for name, size in pairs(item_sizes) do
        F.item_f[name] = uint_field(x .. "item." .. ident(name), name, size, base.DEC)
    end
    local list = {}
    for _, v in pairs(F) do
        if type(v) == "table" then
            for _, w in pairs(v) do list[#list + 1] = w end
        else
            list[#list + 1] = v
        end
    end
    P.proto.fields = list
    P.f = F
    local E = {}
    local G, S = expert.group, expert.severity
    E.crc = ProtoExpert.new(x .. "expert.crc", "Bad CRC", G.CHECKSUM, S.ERROR)
    E.etx = ProtoExpert.new(x .. "expert.etx", "Bad ETX", G.MALFORMED, S.ERROR)
    E.length = ProtoExpert.new(x .. "expert.length", "Length out of range", G.MALFORMED, S.ERROR)
    E.truncated = ProtoExpert.new(x .. "expert.truncated", "Truncated frame", G.MALFORMED, S.ERROR)
    E.format = ProtoExpert.new(x .. "expert.format", "DATA does not fit the opcode", G.MALFORMED, S.WARN)
    E.unknown_op = ProtoExpert.new(x .. "expert.unknown_op", "Unknown opcode", G.UNDECODED, S.WARN)
    E.garbage = ProtoExpert.new(x .. "expert.garbage", "Garbage between frames", G.PROTOCOL, S.WARN)
    E.retransmission = ProtoExpert.new(x .. "expert.retransmission", "Retransmission", G.SEQUENCE, S.NOTE)
    E.repeat_diff = ProtoExpert.new(x .. "expert.seq_repeated", "SEQ repeated with different content", G.SEQUENCE, S.WARN)
    E.gap = ProtoExpert.new(x .. "expert.seq_gap", "SEQ gap", G.SEQUENCE, S.WARN)
    E.nak = ProtoExpert.new(x .. "expert.nak", "NAK", G.SEQUENCE, S.WARN)
    E.ack_orphan = ProtoExpert.new(x .. "expert.ack_orphan", "ACK of no frame seen", G.SEQUENCE, S.WARN)
    E.pending = ProtoExpert.new(x .. "expert.pending", "Incomplete, continues in a later packet", G.REASSEMBLE, S.CHAT)
    P.proto.experts = { E.crc, E.etx, E.length, E.truncated, E.format, E.unknown_op, E.garbage,
        E.retransmission, E.repeat_diff, E.gap, E.nak, E.ack_orphan, E.pending }
    P.e = E
    -- the wire profile, chosen by a preference (default: the bench's)
    local choices, default = {}, 1
    for k, name in ipairs(P.names) do
        choices[k] = { k, name, k }
        if name == KTCS.defaults[protocol] then default = k end
    end
    P.proto.prefs.profile = Pref.enum("Wire profile", default,
        "The wire profile of the capture (from protocols/*.yaml or --profile)", choices, false)
    P.codecs = {}
    return P
end

local function codec_of(P)
    local name = P.names[P.proto.prefs.profile] or P.names[1]
    if not P.codecs[name] then P.codecs[name] = new_codec(KTCS.profiles[name]) end
    return P.codecs[name]
end

---------------------------------------------------------------------------------------------
-- ARQ analysis (after ktcs_bench/capture/arq.py, with frame numbers). An ACK is linked to the
-- last data frame of the other direction with its SEQ, a NAK to the last frame (bad ones too)
-- of the other direction with the SEQ it refuses. A data frame is a retransmission when one of
-- the last few frames of its direction had its SEQ and either its bytes or a bad CRC the peer
-- NAKed (Type I resends one frame; Type II goes back and resends from the refused one).
---------------------------------------------------------------------------------------------
local ARQ_WINDOW = 16  -- frames of one direction within which a repeated SEQ is a resend

local function new_arq_dir()
    return { count = 0, last_seq = nil, data_by_seq = {}, any_by_seq = {}, nak_waiting = {} }
end

local function is_control(c, op)
    local opc = c.p.opcodes[op]
    return opc ~= nil and (opc.name == "ACK" or opc.name == "NAK")
end

local function arq_observe(c, d, rev, r)
    if r.kind ~= "frame" or r.seq == nil then return end
    local a = d.arq
    local function recent(x, of) return x and of.count - x.arq_index <= ARQ_WINDOW end
    -- a NAK decoded before the frame it refuses (a bad frame whose header ends in a later
    -- packet): it refuses this frame, not an older one with the SEQ
    local function nak_waiting()
        local w = a.nak_waiting[r.seq]
        a.nak_waiting[r.seq] = nil
        if w and r.pnum <= w.pnum and (w.nak_target == nil or w.nak_target.pnum < r.pnum) then
            local old = w.nak_target
            if old and old.naked_in == w.pnum then old.naked_in = nil end
            w.nak_to, w.nak_target = r.pnum, r
            r.naked_in = r.naked_in or w.pnum
        end
    end
    if r.err then
        a.count = a.count + 1
        r.arq_index = a.count
        nak_waiting()
        -- a bad frame resending one the peer NAKed: a later good copy is a retransmission of
        -- the first transmission, and counts this one too
        local p = a.any_by_seq[r.seq]
        if recent(p, a) and p.naked_in and not (p.op and is_control(c, p.op)) then
            r.first_tx, r.transmission = p.first_tx or p, (p.transmission or 1) + 1
        end
        a.any_by_seq[r.seq] = r
        return
    end
    local opc = c.p.opcodes[r.op]
    local name = opc and opc.name
    if name == "ACK" then
        local target = rev and rev.arq.data_by_seq[r.seq]
        if target then
            r.ack_to = target.pnum
            target.acked_in = target.acked_in or r.pnum
        else
            r.ack_orphan = true
        end
        return
    end
    if name == "NAK" then
        local seq = r.seq
        if c.field.sub then  -- Type II: the reason is SUB, DATA the refused SEQ
            seq = (r.data_end > r.data_start) and byte_at(r.raw, r.data_start) or r.seq
        end
        r.nak_seq = seq
        local target = rev and rev.arq.any_by_seq[seq]
        if recent(target, rev and rev.arq) then  -- not a frame long gone that had the SEQ
            r.nak_to = target.pnum
            r.nak_target = target
            target.naked_in = target.naked_in or r.pnum
        end
        if rev then rev.arq.nak_waiting[seq] = r end
        return
    end
    a.count = a.count + 1
    r.arq_index = a.count
    nak_waiting()
    local good, bad = a.data_by_seq[r.seq], a.any_by_seq[r.seq]
    local prev
    if recent(good, a) and good.raw == r.raw then
        prev = good  -- sent again intact (its ACK was lost, or Type II went back past it)
    elseif recent(bad, a) and bad.err and bad.naked_in and not (bad.op and is_control(c, bad.op)) then
        prev = bad   -- the peer NAKed it bad (CRC, LEN or ETX)
    end
    if prev then
        local first = prev.first_tx or prev
        r.first_tx = first
        r.retrans_of, r.transmission = first.pnum, (prev.transmission or 1) + 1
    elseif recent(good, a) and a.last_seq == r.seq then
        r.repeat_diff = true
    elseif a.last_seq and r.seq ~= (a.last_seq + 1) % c.p.seq_modulo then
        r.gap_expected = (a.last_seq + 1) % c.p.seq_modulo
    end
    a.last_seq = r.seq
    a.data_by_seq[r.seq] = r
    a.any_by_seq[r.seq] = r
end

---------------------------------------------------------------------------------------------
-- Display
---------------------------------------------------------------------------------------------
local function hexw(v, size) return sfmt("0x%0" .. (2 * size) .. "X", v) end

local function crc_words(c, r)
    if r.crc_packet == nil then return "Packet = [--]-[--], Cal = [--]-[--]" end
    local function cells(v)
        local out = {}
        for k = 0, c.crc.size - 1 do
            local shift = c.little and k or (c.crc.size - 1 - k)
            out[#out + 1] = sfmt("[%02X]", math.floor(v / 256 ^ shift) % 256)
        end
        return table.concat(out, "-")
    end
    return "Packet = " .. cells(r.crc_packet) .. ", Cal = " .. cells(r.crc_calc)
end

local ERROR_WORDS = { crc = "CRC error", etx = "ETX error", length = "length error",
    truncated = "truncated", format = "format error" }

local function reason_name(c, opc, value)
    if opc.reasons and opc.reasons[value] then return opc.reasons[value] end
    if opc.name == "NAK" and c.p.nak_reasons[value] then return c.p.nak_reasons[value] end
    return nil
end

-- A short description of a record, for the Info column and the protocol item.
local function summary(c, r, opc, parsed, perr)
    if r.kind == "garbage" then return sfmt("garbage (%d bytes)", #r.raw) end
    local parts = {}
    local err = r.err or (perr and "format")
    if err then parts[#parts + 1] = "[" .. ERROR_WORDS[err] .. "]" end
    if r.retrans_of then parts[#parts + 1] = "[Retransmission]" end
    if r.seq ~= nil then
        parts[#parts + 1] = "SEQ " .. hexw(r.seq, c.field.seq.size)
        parts[#parts + 1] = opc and opc.name or ("OP " .. hexw(r.op, c.field.op.size))
        if r.sub ~= nil then
            local sname = opc and opc.subs and opc.subs[r.sub]
            parts[#parts + 1] = sname and ("(" .. sname .. ")") or ("sub " .. r.sub)
        end
    end
    if parsed then
        for _, fv in ipairs(parsed.fields) do
            local rn = (fv.spec.name == "reason") and reason_name(c, opc, fv.value)
            parts[#parts + 1] = fv.spec.name .. "=" .. fv.value .. (rn and (" (" .. rn .. ")") or "")
        end
        if parsed.items then parts[#parts + 1] = #parsed.items .. " items" end
        if parsed.statuses then parts[#parts + 1] = parsed.statuses.count .. " codes" end
    end
    if r.ack_to then parts[#parts + 1] = "(of #" .. r.ack_to .. ")" end
    return table.concat(parts, " ")
end

-- What ties a frame to others: its ARQ links and the packet its first byte came in. A frame
-- with a bad LEN shows them too (the peer NAKs it, the sender resends it).
local function show_links(P, c, r, opc, t)
    local F, E = P.f, P.e
    if r.ack_to then t:add(F.ack_to, r.ack_to):set_generated() end
    if r.ack_orphan then
        t:add_proto_expert_info(E.ack_orphan, sfmt("ACK of SEQ %s: no frame with that SEQ seen from the peer", hexw(r.seq, c.field.seq.size)))
    end
    if r.nak_seq ~= nil then
        local reason = c.field.sub and r.sub or (r.data_end > r.data_start and byte_at(r.raw, r.data_start)) or nil
        local rn = reason and (c.p.nak_reasons[reason] or (opc and opc.subs and opc.subs[reason]))
        local what = reason and sfmt("reason %d (%s) ", reason, rn or "unknown") or ""
        t:add_proto_expert_info(E.nak, sfmt("NAK %sfor SEQ %s: expect a retransmission", what, hexw(r.nak_seq, c.field.seq.size)))
        if r.nak_to then t:add(F.nak_to, r.nak_to):set_generated() end
    end
    if r.acked_in then t:add(F.acked_in, r.acked_in):set_generated() end
    if r.naked_in then t:add(F.naked_in, r.naked_in):set_generated() end
    if r.retrans_of then
        t:add(F.retrans_of, r.retrans_of):set_generated()
        t:add(F.transmission, r.transmission):set_generated()
        t:add_proto_expert_info(E.retransmission, sfmt("Retransmission of SEQ %s (transmission %d, first in frame %d)",
            hexw(r.seq, c.field.seq.size), r.transmission, r.retrans_of))
    end
    if r.repeat_diff then
        t:add_proto_expert_info(E.repeat_diff, sfmt("SEQ %s repeated with different content", hexw(r.seq, c.field.seq.size)))
    end
    if r.gap_expected then
        t:add_proto_expert_info(E.gap, sfmt("SEQ gap: expected %s, got %s", hexw(r.gap_expected, c.field.seq.size), hexw(r.seq, c.field.seq.size)))
    end
    if r.first_in then t:add(F.first_in, r.first_in):set_generated() end
end

-- Add one record to the tree. `ft` is a Tvb holding exactly r.raw at offset 0.
local function show_record(P, c, r, ft, pinfo, tree, infos)
    local F, E = P.f, P.e
    local n = #r.raw
    if r.kind == "garbage" then
        local t = tree:add(P.proto, ft(0, n), P.title .. ", " .. summary(c, r))
        t:add(F.offset, r.start):set_generated()
        t:add(F.garbage, ft(0, n))
        t:add_proto_expert_info(E.garbage, sfmt("%d bytes that belong to no frame (resynchronised)", n))
        infos[#infos + 1] = summary(c, r)
        return
    end
    local opc = (r.op ~= nil) and c.p.opcodes[r.op] or nil
    local parsed, perr
    if r.err == nil and opc then parsed, perr = parse_payload(c, opc, ssub(r.raw, r.data_start + 1, r.data_end)) end
    local text = summary(c, r, opc, parsed, perr)
    infos[#infos + 1] = text
    local t = tree:add(P.proto, ft(0, n), P.title .. " (" .. c.name .. "), " .. text)
    t:add(F.profile, c.name):set_generated()
    t:add(F.offset, r.start):set_generated()
    t:add(F.stx, ft(0, 1))
    for _, h in ipairs(c.p.header) do
        local v = r[h.name]
        if v ~= nil then
            -- a record cut at an STX inside its header still has the values read from it
            local inside = h.offset + h.size <= n
            local function add(field, value)
                if inside then return t:add(field, ft(h.offset, h.size), value) end
                local it = t:add(field, value)
                it:set_generated()
                return it
            end
            if h.name == "op" then
                local it = add(F.op, v)
                if opc then
                    it:append_text(" (" .. opc.name .. ")")
                    t:add(F.op_name, opc.name):set_generated()
                else
                    it:append_text(" (unknown)")
                    t:add_proto_expert_info(E.unknown_op, "Unknown opcode " .. hexw(v, h.size) .. ": the receiver NAKs it (length/format)")
                end
            elseif h.name == "sub" then
                local it = add(F.sub, v)
                local sname = opc and opc.subs and opc.subs[v]
                if sname then
                    it:append_text(" (" .. sname .. ")")
                    t:add(F.sub_name, sname):set_generated()
                end
            else
                add(F[h.name], v)
            end
        end
    end
    if r.err == "length" then
        local what
        if r.len - c.fixed < 0 then
            what = sfmt("LEN %d is less than the %d header bytes it counts", r.len, c.fixed)
        else
            what = sfmt("LEN %d is over the profile's maximum %d", r.len, c.max_len)
        end
        t:add(F.error, "length"):set_generated()
        t:add_proto_expert_info(E.length, what)
        t:add(F.crc_ok, false):set_generated()
        show_links(P, c, r, opc, t)
        return
    end
    if r.data_end > r.data_start then t:add(F.data, ft(r.data_start, r.data_end - r.data_start)) end
    -- the trailer, as far as this record holds it
    local cr = c.crc
    local at = r.data_end
    local full = (r.err ~= "truncated") and (at + c.trailer == n)
    if r.crc_packet ~= nil then
        if full then
            t:add(F.crc, ft(at, cr.size), r.crc_packet)
        else
            t:add(F.crc, r.crc_packet):set_generated()
        end
        t:add(F.crc_calc, r.crc_calc):set_generated()
    end
    local crc_ok = r.crc_packet ~= nil and r.crc_packet == r.crc_calc
    t:add(F.crc_ok, crc_ok):set_generated()
    if full and cr.pad > 0 then t:add(F.crc_pad, ft(at + cr.size, cr.pad)) end
    if full and c.etx then t:add(F.etx, ft(n - 1, 1)) end
    if r.err then t:add(F.error, r.err):set_generated() end
    if r.err == "crc" then
        local why = crc_ok and "the CRC padding bytes are not zero" or "the CRC does not check"
        t:add_proto_expert_info(E.crc, sfmt("Bad CRC (%s): %s", why, crc_words(c, r)))
    elseif r.err == "etx" then
        t:add_proto_expert_info(E.etx, sfmt("Bad ETX: 0x%02X, expected 0x%02X", byte_at(r.raw, n - 1), c.etx))
    elseif r.err == "truncated" then
        local need = ""
        if r.len then
            need = sfmt(" of the %d its LEN announces", c.hs + (r.len - c.fixed) + c.trailer)
        end
        t:add_proto_expert_info(E.truncated, sfmt("Truncated: %d bytes%s (the capture ends before the frame does)", n, need))
    elseif r.err then
        t:add_proto_expert_info(E.crc, crc_words(c, r))
    end
    if perr then
        t:add(F.error, "format"):set_generated()
        t:add_proto_expert_info(E.format, perr)
    end
    if parsed then
        local base_off = r.data_start
        for _, fv in ipairs(parsed.fields) do
            local abbr = P.short .. "." .. ident(opc.name) .. "." .. ident(fv.spec.name)
            local it = t:add(F.payload[abbr], ft(base_off + fv.offset, fv.spec.size), fv.value)
            local rn = (fv.spec.name == "reason") and reason_name(c, opc, fv.value)
            if rn then it:append_text(" (" .. rn .. ")") end
            if fv.spec.name == "code" and code_name(fv.value) then it:append_text(" (" .. code_name(fv.value) .. ")") end
            if opc.name == "REQUEST_ALL" and fv.spec.name == "count" and #parsed.fields >= 2 then
                local start = parsed.fields[1].value
                it:append_text(sfmt(" -> codes [%d]-[%d]", start, start + fv.value - 1))
            end
        end
        if parsed.items then t:add(F.items, #parsed.items):set_generated() end
        if parsed.statuses then t:add(F.items, parsed.statuses.count):set_generated() end
        for k, item in ipairs(parsed.items or {}) do
            local words = {}
            for _, fv in ipairs(item.values) do
                local w = fv.spec.name .. " " .. fv.value
                if fv.spec.name == "code" and code_name(fv.value) then w = w .. " (" .. code_name(fv.value) .. ")" end
                words[#words + 1] = w
            end
            local it = t:add(F.item, ft(base_off + item.offset, opc.item_size))
            it:set_text(sfmt("Item %d: %s", k, table.concat(words, ", ")))
            for _, fv in ipairs(item.values) do
                local sub = it:add(F.item_f[fv.spec.name], ft(base_off + fv.offset, fv.spec.size), fv.value)
                if fv.spec.name == "code" and code_name(fv.value) then sub:append_text(" (" .. code_name(fv.value) .. ")") end
            end
        end
        if parsed.statuses then
            local s0 = base_off + parsed.statuses.offset
            for k = 1, parsed.statuses.count do
                local v = byte_at(r.raw, s0 + k - 1)
                local it = t:add(F.status, ft(s0 + k - 1, 1), v)
                local nm = code_name(k)
                it:set_text(sfmt("Code %d%s: %d", k, nm and (" " .. nm) or "", v))
            end
        end
    end
    show_links(P, c, r, opc, t)
end

-- A Tvb holding exactly the record's bytes: a slice of this packet when they all lie in it,
-- else a new data source ("reassembled").
local function record_tvb(tvb, r, pkt_start)
    local rel = r.start - pkt_start
    if rel >= 0 and rel + #r.raw <= tvb:len() then return tvb(rel, #r.raw):tvb() end
    return ByteArray.new(r.raw, true):tvb(sfmt("ktcs record @%d", r.start))
end

local function set_columns(P, pinfo, infos)
    pinfo.cols.protocol = P.column
    if #infos > 0 then pinfo.cols.info = table.concat(infos, " | ") end
end

---------------------------------------------------------------------------------------------
-- Stream mode: each direction's bytes accumulated and decoded by us (Type I always; Type II
-- when TCP cannot reassemble for us). Pass one records which packet holds each record's last
-- byte; every pass shows a packet's records from there.
---------------------------------------------------------------------------------------------
local function new_state()
    return { dirs = {}, pkts = {}, calls = {} }
end

local function new_dir(key, name)
    return { key = key, name = name, buf = "", base = 0, pend = nil, st = { suspect_until = 0 },
        packets = {}, arq = new_arq_dir() }
end

local function packet_of(d, offset)
    for k = #d.packets, 1, -1 do
        local p = d.packets[k]
        if p.start <= offset and offset < p.stop then return p end
    end
    return nil
end

local function stream_feed(S, c, d, rev, pinfo, tvb)
    local pk = { dir = d, start = d.base + #d.buf, records = {}, parts = {} }
    pk.stop = pk.start + tvb:len()
    pk.num = pinfo.number
    S.pkts[pinfo.number] = pk
    d.packets[#d.packets + 1] = pk
    d.last_num = pinfo.number
    d.buf = d.buf .. tvb:raw()
    local recs, keep, pend = decode(c, d.buf, d.base, d.st)
    for _, r in ipairs(recs) do
        local home = packet_of(d, r.start + #r.raw - 1) or pk
        r.pnum = home.num
        home.records[#home.records + 1] = r
        local first = packet_of(d, r.start)
        if first and first.num ~= home.num then r.first_in = first.num end
        for k = #d.packets, 1, -1 do
            local p = d.packets[k]
            if p.stop <= r.start then break end
            if p ~= home and p.start < r.start + #r.raw then p.parts[#p.parts + 1] = home.num end
        end
        arq_observe(c, d, rev(d), r)
    end
    d.buf = ssub(d.buf, keep + 1)
    d.base = d.base + keep
    d.pend = pend and (pend - keep) or nil
end

local function stream_show(P, S, c, d, pk, tvb, pinfo, tree)
    local infos = {}
    for _, r in ipairs(pk.records) do
        show_record(P, c, r, record_tvb(tvb, r, pk.start), pinfo, tree, infos)
    end
    local unresolved = d.base + #d.buf
    if pinfo.visited and d.last_num == pk.num and #d.buf > 0 then
        -- the capture ends here: what the decoder still holds is reported as it stands
        for _, r in ipairs(close_records(c, d.buf, d.base, d.pend)) do
            r.pnum = pk.num
            local first = packet_of(d, r.start)
            if first and first.num ~= pk.num then r.first_in = first.num end
            show_record(P, c, r, record_tvb(tvb, r, pk.start), pinfo, tree, infos)
        end
    elseif not pinfo.visited and pk.stop > d.base and #d.buf > 0 then
        -- first pass: these bytes wait for what comes next (a two-pass run shows them resolved)
        local from = math.max(d.base, pk.start)
        tree:add(P.proto, tvb()):add_proto_expert_info(P.e.pending,
            sfmt("%d bytes from stream offset %d wait for the rest of their frame", unresolved - from, from))
        infos[#infos + 1] = "[incomplete, continues in a later packet]"
    end
    local seen = {}
    for _, num in ipairs(pk.parts) do
        if not seen[num] then
            seen[num] = true
            local t = tree:add(P.proto, tvb(), P.title .. ", bytes of the record shown in frame " .. num)
            t:add(P.f.shown_in, num):set_generated()
            if #pk.records == 0 then infos[#infos + 1] = "[part of a record shown in #" .. num .. "]" end
        end
    end
    set_columns(P, pinfo, infos)
end

---------------------------------------------------------------------------------------------
-- ktcs1: Type I in LINKTYPE_USER0 captures. A direction is the packets' flag direction (the
-- bench writes outbound/inbound) on one interface; the interface is known only when the first
-- pass builds a tree (Wireshark does; tshark without a read filter does not, and then the
-- flag direction alone tells the two directions of a link apart).
---------------------------------------------------------------------------------------------
local T1 = new_proto("type1", "ktcs1", "kTCS Type I")
T1.column = "kTCS1"
local S1 = new_state()

local function try_field(name)
    local ok, f = pcall(Field.new, name)
    return ok and f or nil
end
local f_if_id = try_field("frame.interface_id")
local f_if_name = try_field("frame.interface_name")

local function field_value(f)
    if not f then return nil end
    local v = f()
    return v and v.value
end

local function dir_name_reverse(name)
    local a, b = name:match("^(.-)>(.-)$")
    if a and b and a ~= "" and b ~= "" then return b .. ">" .. a end
    return nil
end

local function reverse_of(S)
    return function(d)
        if d.rev and S.dirs[d.rev] then return S.dirs[d.rev] end
        local want = dir_name_reverse(d.name)
        local others = {}
        for key, o in pairs(S.dirs) do
            if o ~= d then
                if want and o.name == want then
                    d.rev, o.rev = key, d.key
                    return o
                end
                others[#others + 1] = o
            end
        end
        if #others == 1 and not want then return others[1] end
        return nil
    end
end

function T1.proto.init()
    S1 = new_state()
    T1.codecs = {}
end

function T1.proto.dissector(tvb, pinfo, tree)
    local c = codec_of(T1)
    local pk = S1.pkts[pinfo.number]
    if not pk then
        local id = field_value(f_if_id) or 0
        local key = tostring(id) .. "/" .. tostring(pinfo.p2p_dir)
        local d = S1.dirs[key]
        if not d then
            d = new_dir(key, field_value(f_if_name) or key)
            S1.dirs[key] = d
        end
        stream_feed(S1, c, d, reverse_of(S1), pinfo, tvb)
        pk = S1.pkts[pinfo.number]
    end
    stream_show(T1, S1, c, pk.dir, pk, tvb, pinfo, tree)
    local a, b = (field_value(f_if_name) or pk.dir.name):match("^(.-)>(.-)$")
    if a and a ~= "" and b ~= "" then
        pinfo.cols.src, pinfo.cols.dst = a, b
    end
    return tvb:len()
end

DissectorTable.get("wtap_encap"):add(wtap_encaps.USER0, T1.proto)

---------------------------------------------------------------------------------------------
-- ktcs2: Type II over TCP. A frame that starts in a segment and ends in a later one is left to
-- TCP's reassembly (pinfo.desegment_*). Bytes TCP could not hold for us without handing again
-- what we already showed -- its "partial reassembly" keeps a reassembly from its first byte --
-- are carried to the next segment by us, as are all held bytes when TCP reassembly is off or
-- before the direction has shown anything (so everything is shown in a second pass). Where a
-- handed-over tvb starts in the stream follows from what TCP was asked: `d.expect`.
---------------------------------------------------------------------------------------------
local T2 = new_proto("type2", "ktcs2", "kTCS Type II")
T2.column = "kTCS2"
local S2 = new_state()
T2.proto.prefs.tcp_ports = Pref.range("TCP ports", "", "TCP ports decoded as kTCS Type II (besides Decode As and the heuristic)", 65535)

-- (tcp.stream would be nicer, but fields are not filled in a first pass without a tree)
local function tcp_key(pinfo, reverse)
    local a = tostring(pinfo.src) .. ":" .. tostring(pinfo.src_port)
    local b = tostring(pinfo.dst) .. ":" .. tostring(pinfo.dst_port)
    if reverse then a, b = b, a end
    return a .. ">" .. b, a .. ">" .. b
end

local function t2_dir(pinfo)
    local key, name = tcp_key(pinfo, false)
    local d = S2.dirs[key]
    if not d then
        d = new_dir(key, name)
        d.rev = tcp_key(pinfo, true)
        d.next, d.expect, d.seg_end, d.carry = 0, 0, 0, ""
        S2.dirs[key] = d
    end
    return d
end

function T2.proto.init()
    S2 = new_state()
    T2.codecs = {}
end

-- Pass one: decode the carried bytes and the tvb's bytes not consumed yet; decide who holds
-- what is left. Returns the call, remembered for later passes.
local function t2_decode(c, d, tvb, pinfo)
    local n = tvb:len()
    local start = d.expect  -- stream offset of tvb[0]
    local skip = math.max(0, math.min(n, d.next - start))  -- already consumed (TCP handed it again)
    local call = { carry = d.carry, raw = tvb:raw(), start = start, num = pinfo.number }
    local buf = call.carry .. ssub(call.raw, skip + 1)
    call.base = start + skip - #call.carry  -- stream offset of buf[0]
    local recs, keep, pend = decode(c, buf, call.base, d.st)
    call.records = recs
    for _, r in ipairs(recs) do
        r.pnum = pinfo.number
        arq_observe(c, d, S2.dirs[d.rev], r)
    end
    -- a tvb ends where its last segment does; what precedes the previous end is reassembled
    local old_len = math.max(0, d.seg_end - start)
    d.next, d.carry, d.expect, d.seg_end = call.base + keep, "", start + n, start + n
    if keep < #buf then
        call.rest, call.pend, call.rest_base = ssub(buf, keep + 1), pend and (pend - keep), call.base + keep
        local k = keep - #call.carry + skip  -- where the held bytes start in the tvb
        local tcp_ok = (pinfo.can_desegment or 0) > 0 and keep >= #call.carry
        if tcp_ok and k > 0 and k > old_len then
            call.deseg, d.expect = k, start + k                 -- a new reassembly from k
        elseif tcp_ok and k == 0 and #recs == 0 and d.delivered then
            call.deseg, call.hidden, d.expect = 0, true, start  -- the reassembly grows
        else
            d.carry = call.rest
            call.carried = #d.carry
        end
    end
    if not call.hidden then
        d.delivered = call
    end
    d.latest = call
    return call
end

local function t2_find(calls, tvb)
    local raw = tvb:raw()
    for _, call in ipairs(calls or {}) do
        if ssub(call.raw, 1, #raw) == raw and not call.hidden then return call end
    end
    return nil
end

function T2.proto.dissector(tvb, pinfo, tree)
    local c = codec_of(T2)
    local d = t2_dir(pinfo)
    local key = tostring(pinfo.number) .. "/" .. d.key
    local call
    if not pinfo.visited then
        call = t2_decode(c, d, tvb, pinfo)
        S2.calls[key] = S2.calls[key] or {}
        table.insert(S2.calls[key], call)
    else
        call = t2_find(S2.calls[key], tvb)
        if not call then return 0 end
    end
    local infos = {}
    for _, r in ipairs(call.records) do
        show_record(T2, c, r, record_tvb(tvb, r, call.start), pinfo, tree, infos)
    end
    local last = d.latest
    if pinfo.visited and d.delivered == call and last.rest then
        -- the stream ends with bytes still held: reported as they stand, in the last packet
        -- a second pass shows of this direction
        for _, r in ipairs(close_records(c, last.rest, last.rest_base, last.pend)) do
            r.pnum = pinfo.number
            show_record(T2, c, r, record_tvb(tvb, r, call.start), pinfo, tree, infos)
        end
    elseif call.carried then
        tree:add(T2.proto, tvb()):add_proto_expert_info(T2.e.pending,
            sfmt("%d bytes wait for the rest of their frame in a later segment", call.carried))
        infos[#infos + 1] = "[incomplete, continues in a later segment]"
    end
    if call.deseg then
        pinfo.desegment_offset = call.deseg
        pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
    end
    set_columns(T2, pinfo, infos)
    return tvb:len()
end

-- The heuristic: a segment that starts with a complete frame whose LEN, CRC (and ETX) check.
local function heuristic(tvb, pinfo, tree)
    local c = codec_of(T2)
    local n = tvb:len()
    if n < c.hs + c.trailer then return false end
    local raw = tvb:raw(0, math.min(n, c.hs + c.max_len + c.trailer))
    if valid_at(c, raw, 0, #raw) ~= true then return false end
    pcall(function() pinfo.conversation = T2.proto end)
    T2.proto.dissector(tvb, pinfo, tree)
    return true
end

local tcp_table = DissectorTable.get("tcp.port")
tcp_table:add_for_decode_as(T2.proto)
T2.proto:register_heuristic("tcp", heuristic)
local ports_now = ""
function T2.proto.prefs_changed()
    local want = T2.proto.prefs.tcp_ports
    if want ~= ports_now then
        if ports_now ~= "" then tcp_table:remove(ports_now, T2.proto) end
        if want ~= "" then tcp_table:add(want, T2.proto) end
        ports_now = want
    end
end

---------------------------------------------------------------------------------------------
-- Self-check at load: each profile's CRC table gives its algorithm's check value.
---------------------------------------------------------------------------------------------
for _, name in ipairs(KTCS.order) do
    local cr = KTCS.profiles[name].crc
    if cr.check and crc_of(cr, "123456789", 0, 9) ~= cr.check then
        error(sfmt("ktcs: profile %s: CRC %s does not give its check value 0x%X", name, cr.name, cr.check))
    end
end
