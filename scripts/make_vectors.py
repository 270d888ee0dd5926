#!/usr/bin/env python3
"""Makes the project's own MAVLink test vectors and codec benchmark input with
the reference implementation, pymavlink (pinned in scripts/requirements-interop.txt).

    .venv/bin/python scripts/make_vectors.py [--vectors DIR] [--bench FILE]

Defaults: test/vectors/ and bench/data/telemetry_mix.bin. scripts/bootstrap runs
it when they are missing or when this script, the pinned requirements or the
dialect lock changed; the output is git-ignored (several MB that this script
rebuilds byte for byte, so committing them would only duplicate it).

Everything is drawn from fixed seeds and written in a fixed order, so the files
are the same on every machine with the same pymavlink. The formats are those of
the shared vectors (../shared/mavlink/vectors/README.md, when present) and are
summed up in test/vectors/README.md, which this script writes too:

  ardupilotmega.v2.jsonl      every message of the dialect x 8 instances, MAVLink 2
  ardupilotmega.v1.jsonl      the same instances of every message with id < 256, MAVLink 1
  ardupilotmega.signed.jsonl  2 of the 8 instances of every message, MAVLink 2 signed
  crc_extra.json              per message id: name, CRC_EXTRA, min/max payload length
  stream.bin                  valid frames interleaved with garbage and damaged frames
  stream.expected.jsonl       exactly the frames a correct parser returns from stream.bin
  stream.layout.jsonl         what each byte range of stream.bin is

Every record is checked before it is written: pymavlink parses the frame into
exactly one message with the recorded header and fields, and encoding those
fields again reproduces the frame. The stream is checked with pymavlink's own
robust parser (which skips a bad candidate's whole declared length) and with a
parser that rescans one byte after a failed candidate: both must return exactly
the expected frames. Any failed check aborts with a message saying which record.
"""

import argparse
import contextlib
import glob
import hashlib
import io
import json
import math
import os
import random
import struct
import sys

from pymavlink.dialects.v20 import ardupilotmega as dialect
from pymavlink.generator import mavparse

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SEED = 20240601
K = 8
SIGNED_PER_MESSAGE = 2
STREAM_FRAMES = 1500
# SHA-256 of the ASCII string "mavlink-vectors/visible/signing-key": the key of
# the shared vectors, so that one signing state reads both sets.
KEY = hashlib.sha256(b"mavlink-vectors/visible/signing-key").digest()

FLT_MAX = struct.unpack("<f", struct.pack("<I", 0x7F7FFFFF))[0]
FLT_TRUE_MIN = struct.unpack("<f", struct.pack("<I", 1))[0]
DBL_MAX = sys.float_info.max
DBL_TRUE_MIN = 5e-324
INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1), "uint8_t": (0, 2**8 - 1),
    "int16_t": (-(2**15), 2**15 - 1), "uint16_t": (0, 2**16 - 1),
    "int32_t": (-(2**31), 2**31 - 1), "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1), "uint64_t": (0, 2**64 - 1),
}


class Fail(Exception):
    pass


def check(ok, what):
    if not ok:
        raise Fail(what)


# ---------------------------------------------------------------- the dialect

class Message:
    """One message of the dialect: pymavlink's class and the XML's fields."""

    def __init__(self, cls, xml):
        self.cls, self.id, self.name = cls, cls.id, cls.msgname
        self.crc_extra, self.min_len, self.max_len = xml.crc_extra, xml.wire_min_length, xml.wire_length
        ext = len(xml.fields) if xml.extensions_start is None else xml.extensions_start
        # (name, type, array length or 0, extension?) in XML declaration order
        self.fields = [(f.name, f.type, f.array_length, i >= ext) for i, f in enumerate(xml.fields)]
        check(list(cls.fieldnames) == [f[0] for f in self.fields], "%s: pymavlink and the XML disagree on the fields" % self.name)
        check(cls.crc_extra == self.crc_extra, "%s: pymavlink's CRC_EXTRA %d, the XML's %d" % (self.name, cls.crc_extra, self.crc_extra))
        check(cls.unpacker.size == self.max_len, "%s: pymavlink's length %d, the XML's %d" % (self.name, cls.unpacker.size, self.max_len))


def load_dialect():
    """The messages of ardupilotmega, read from the dialect XML that scripts/bootstrap
    copied into priv/mavlink/ (what the codec is generated from)."""
    xml = {}
    files = sorted(glob.glob(os.path.join(ROOT, "priv", "mavlink", "*.xml")))
    check(files, "no dialect XML in priv/mavlink/ (run scripts/bootstrap first)")
    for path in files:
        # mavparse prints warnings about the XML's enums on stdout; they concern
        # neither the messages nor their wire format.
        with contextlib.redirect_stdout(io.StringIO()):
            parsed = mavparse.MAVXML(path, mavparse.PROTOCOL_2_0)
        for m in parsed.message:
            xml[m.id] = m
    messages = []
    for msg_id in sorted(dialect.mavlink_map):
        check(msg_id in xml, "message id %d of pymavlink is in none of %s" % (msg_id, files))
        messages.append(Message(dialect.mavlink_map[msg_id], xml[msg_id]))
    return messages


# ------------------------------------------------------------- field values

def f32(x):
    """x rounded to float32 (what the wire holds), as a Python float."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def random_int(rng, ty):
    lo, hi = INT_RANGES[ty]
    kind = rng.random()
    if kind < 0.5:
        return rng.randint(lo, hi)
    if kind < 0.8:
        return max(lo, min(hi, rng.randint(-100, 100)))
    return rng.choice([lo, hi, 0, 1, max(lo, -1)])


def random_float(rng, double):
    top, tiny = (DBL_MAX, DBL_TRUE_MIN) if double else (FLT_MAX, FLT_TRUE_MIN)
    max_exp = 307 if double else 37
    min_exp = -323 if double else -44
    kind = rng.random()
    if kind < 0.4:
        x = rng.uniform(-1000.0, 1000.0)
    elif kind < 0.7:
        x = rng.choice([-1, 1]) * 10.0 ** rng.uniform(min_exp, max_exp)
    elif kind < 0.8:
        # subnormals
        x = rng.choice([-1, 1]) * tiny * rng.randint(1, 2**20)
    else:
        x = rng.choice([0.0, -0.0, math.nan, math.inf, -math.inf, top, -top, tiny, -tiny, 1.0, -1.0])
    return x if double else f32(x)


def random_char(rng, n, full=False):
    length = n if full else rng.choice([0, n, rng.randint(0, n)])
    return bytes(rng.randint(0x20, 0x7E) for _ in range(length))


def draw_scalar(rng, ty, profile):
    if ty in INT_RANGES:
        lo, hi = INT_RANGES[ty]
        return {"zero": 0, "max": hi, "min": lo}[profile] if profile in ("zero", "max", "min") else random_int(rng, ty)
    double = ty == "double"
    if profile == "zero":
        return 0.0
    if profile == "max":
        return rng.choice([DBL_MAX, math.inf, math.nan, 1e308] if double else [FLT_MAX, math.inf, math.nan, f32(1e38)])
    if profile == "min":
        return rng.choice([-DBL_MAX, -math.inf, -DBL_TRUE_MIN, -0.0] if double else [-FLT_MAX, -math.inf, -FLT_TRUE_MIN, -0.0])
    return random_float(rng, double)


def zero_of(ty, n):
    if ty == "char":
        return b""
    z = 0.0 if ty in ("float", "double") else 0
    return [z] * n if n else z


def draw_field(rng, ty, n, profile):
    if profile == "sparse" and rng.random() < 0.5:
        return zero_of(ty, n)
    if ty == "char":
        return b"" if profile == "zero" else random_char(rng, n, full=profile in ("max", "min"))
    inner = "random" if profile == "sparse" else profile
    if not n:
        return draw_scalar(rng, ty, inner)
    values = [draw_scalar(rng, ty, inner) for _ in range(n)]
    if profile == "sparse" and rng.random() < 0.5:
        keep = rng.randint(0, n - 1)
        values[keep:] = [zero_of(ty, 0)] * (n - keep)
    return values


def is_zero(v):
    if isinstance(v, list):
        return all(is_zero(x) for x in v)
    if isinstance(v, float):
        return v == 0.0 and math.copysign(1.0, v) > 0
    return not v


def draw_values(rng, msg, profile):
    values = {name: draw_field(rng, ty, n, profile) for name, ty, n, _ in msg.fields}
    ext = [f for f in msg.fields if f[3]]
    # An instance whose extension fields are all zero would not tell a decoder
    # that drops them from one that reads them.
    while profile == "random" and ext and all(is_zero(values[f[0]]) for f in ext):
        for name, ty, n, _ in ext:
            values[name] = draw_field(rng, ty, n, profile)
    return values


def profiles(rng):
    return ["zero", "max", "min", "sparse"] + [rng.choice(["random", "sparse"]) for _ in range(K - 4)]


# ------------------------------------------------------------- frames

def crc(data, crc_extra):
    c = dialect.x25crc(bytes(data))
    c.accumulate(bytes([crc_extra]))
    return c.crc


def pack(msg, values, version, sysid, compid, seq, signing=None):
    """The frame pymavlink sends, except that a MAVLink 1 payload is cut to the
    message's non-extension length, as the MAVLink C library sends it
    (pymavlink's own force_mavlink1 sends the extension bytes too)."""
    mav = dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    if signing:
        mav.signing.secret_key = KEY
        mav.signing.link_id = signing["link_id"]
        mav.signing.timestamp = signing["timestamp"]
        mav.signing.sign_outgoing = True
    frame = msg.cls(*[values[name] for name, _, _, _ in msg.fields]).pack(mav, force_mavlink1=version == 1)
    if version == 1:
        body = bytearray(frame[:6 + msg.min_len])
        body[1] = msg.min_len
        frame = bytes(body) + struct.pack("<H", crc(body[1:], msg.crc_extra))
    return bytes(frame)


def decode(frame, signed):
    """pymavlink's decoding of one frame, which must be exactly one message."""
    mav = dialect.MAVLink(None)
    if signed:
        mav.signing.secret_key = KEY
    got = mav.parse_buffer(frame) or []
    check(len(got) == 1 and got[0].get_type() != "BAD_DATA" and not got[0].get_type().startswith("UNKNOWN"),
          "pymavlink does not read %s as one message: %r" % (frame.hex(), got))
    check(bool(got[0]._signed) == signed, "pymavlink's signature check on %s" % frame.hex())
    return got[0]


def json_value(v):
    if isinstance(v, list):
        return [json_value(x) for x in v]
    if isinstance(v, float):
        if math.isnan(v):
            return "NaN"
        if math.isinf(v):
            return "Infinity" if v > 0 else "-Infinity"
    return v


def wire_value(v, ty):
    """A decoded field value as the message class takes it again."""
    return v.encode("ascii") if ty == "char" else v


def record(msg, values, version, rng, signing=None, seq=None):
    """A checked record: the frame and the fields pymavlink decodes from it."""
    sysid, compid = rng.randint(0, 255), rng.randint(0, 255)
    seq = rng.randint(0, 255) if seq is None else seq
    frame = pack(msg, values, version, sysid, compid, seq, signing)
    m = decode(frame, signing is not None)
    where = "%s (%d), MAVLink %d" % (msg.name, msg.id, version)
    check(m.get_msgId() == msg.id and (m.get_srcSystem(), m.get_srcComponent(), m.get_seq()) == (sysid, compid, seq), where + ": header")
    fields = {name: getattr(m, name) for name, _, _, _ in msg.fields}
    again = pack(msg, {name: wire_value(fields[name], ty) for name, ty, _, _ in msg.fields}, version, sysid, compid, seq, signing)
    check(again == frame, "%s: re-encoding the decoded fields gives %s, not %s" % (where, again.hex(), frame.hex()))
    rec = {"msg": msg.name, "id": msg.id, "mavlink": version, "signed": signing is not None,
           "sysid": sysid, "compid": compid, "seq": seq,
           "fields": {k: json_value(v) for k, v in fields.items()}, "frame": frame.hex()}
    if signing:
        rec["signing"] = {"secret_key": KEY.hex(), "link_id": signing["link_id"], "timestamp": signing["timestamp"]}
    return rec, frame


def dumps(obj):
    return json.dumps(obj, separators=(",", ":"), allow_nan=False)


# ------------------------------------------------------------- the record sets

def record_sets(messages):
    rng = random.Random(SEED)
    v2, v1, signed = [], [], []
    for msg in messages:
        instances = [(p, draw_values(rng, msg, p)) for p in profiles(rng)]
        for p, values in instances:
            rec, _ = record(msg, values, 2, rng)
            v2.append(dict(rec, profile=p))
        if msg.id < 256:
            for p, values in instances:
                rec, _ = record(msg, values, 1, rng)
                v1.append(dict(rec, profile=p))
        for p, values in rng.sample(instances, SIGNED_PER_MESSAGE):
            signing = {"link_id": rng.randint(0, 255), "timestamp": rng.randint(0, 2**48 - 1)}
            rec, _ = record(msg, values, 2, rng, signing)
            signed.append(dict(rec, profile=p))
    return v2, v1, signed


def crc_table(messages):
    return {str(m.id): {"name": m.name, "crc_extra": m.crc_extra, "min_len": m.min_len, "max_len": m.max_len} for m in messages}


# ------------------------------------------------------------- the stream

def declared_end(buf, at):
    """Where a candidate frame starting with a magic byte at `at` ends, by its
    own length and flags (past the end of `buf` when cut off)."""
    if buf[at] == 0xFE:
        return at + 8 + (buf[at + 1] if at + 1 < len(buf) else 255)
    length = buf[at + 1] if at + 1 < len(buf) else 255
    flags = buf[at + 2] if at + 2 < len(buf) else 1
    return at + 12 + length + (13 if flags & 1 else 0)


def crc_passes(buf, at, by_id):
    """Whether a candidate at `at` is well-formed enough to pass a CRC check."""
    end = declared_end(buf, at)
    if end > len(buf):
        return False
    if buf[at] == 0xFE:
        msg_id, payload_end = buf[at + 5], at + 6 + buf[at + 1]
    else:
        msg_id, payload_end = buf[at + 7] | buf[at + 8] << 8 | buf[at + 9] << 16, at + 10 + buf[at + 1]
    msg = by_id.get(msg_id)
    return msg is not None and crc(buf[at + 1:payload_end], msg.crc_extra) == struct.unpack_from("<H", buf, payload_end)[0]


def rescan(buf, by_id):
    """A parser that rescans one byte after a failed candidate (as the
    project's does): the offsets of the frames whose CRC and signature check."""
    found, at = [], 0
    while at < len(buf):
        if buf[at] in (0xFD, 0xFE) and crc_passes(buf, at, by_id) and (buf[at] == 0xFE or buf[at + 2] in (0, 1)):
            end = declared_end(buf, at)
            if buf[at] == 0xFD and buf[at + 2] & 1 and hashlib.sha256(KEY + bytes(buf[at:end - 6])).digest()[:6] != bytes(buf[end - 6:end]):
                at += 1
                continue
            found.append(at)
            at = end
        else:
            at += 1
    return found


def stream(messages):
    rng = random.Random(SEED + 1)
    by_id = {m.id: m for m in messages}
    v1_messages = [m for m in messages if m.id < 256]
    timestamp = rng.randint(2**40, 2**44)

    def some_frame(version=None):
        nonlocal timestamp
        if version is None:
            version = rng.choices(["v2", "signed", "v1"], [63, 15, 22])[0]
        msg = rng.choice(v1_messages if version == "v1" else messages)
        values = draw_values(rng, msg, rng.choice(["zero", "max", "min", "sparse", "random", "random"]))
        signing = None
        if version == "signed":
            # strictly increasing through the stream: replay protection accepts them all
            timestamp += rng.randint(1, 10**6)
            signing = {"link_id": rng.randint(0, 255), "timestamp": timestamp}
        return record(msg, values, 1 if version == "v1" else 2, rng, signing)

    def flip(frame, lo, hi):
        frame = bytearray(frame)
        at = rng.randrange(lo, hi)
        frame[at] ^= 1 << rng.randrange(8)
        return bytes(frame)

    def error():
        kind = rng.choice(["garbage", "garbage_magic", "truncated", "bad_crc", "corrupt_byte"])
        if kind == "garbage":
            return kind, bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        if kind == "garbage_magic":
            return kind, bytes([rng.choice([0xFD, 0xFE])] + [rng.randrange(256) for _ in range(rng.randint(0, 40))])
        _, frame = some_frame()
        header = 10 if frame[0] == 0xFD else 6
        payload_end = header + frame[1]
        if kind == "truncated":
            return kind, frame[:rng.randint(1, len(frame) - 1)]
        if kind == "bad_crc":
            return kind, flip(frame, payload_end, payload_end + 2)
        # a bit of the header after the length and flags bytes, or of the payload
        return kind, flip(frame, 4 if header == 10 else 2, payload_end)

    def filler(n):
        return bytes(rng.randrange(0xFD) for _ in range(n))

    def damaged_segment():
        """An error and the filler after it (never a magic byte) that outlasts every
        candidate starting in the error, so that a parser skipping a bad
        candidate's declared length is idle again before the next valid frame;
        drawn again when some candidate in it happens to pass a CRC check."""
        while True:
            kind, bad = error()
            ends = [declared_end(bad, i) for i, b in enumerate(bad) if b in (0xFD, 0xFE)]
            seg = bad + filler(max([len(bad)] + ends) - len(bad))
            if not any(crc_passes(seg, i, by_id) for i, b in enumerate(bad) if b in (0xFD, 0xFE)):
                return kind, len(bad), seg

    buf, layout, expected = bytearray(), [], []
    for index in range(STREAM_FRAMES):
        if rng.random() < 0.5:
            kind, error_bytes, seg = damaged_segment()
            layout.append({"offset": len(buf), "length": len(seg), "kind": kind, "error_bytes": error_bytes})
            buf += seg
        rec, frame = some_frame()
        layout.append({"offset": len(buf), "length": len(frame), "kind": "valid", "index": index})
        expected.append(dict({"index": index, "offset": len(buf)}, **rec))
        buf += frame
    while True:
        tail = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        if not any(crc_passes(tail, i, by_id) for i, b in enumerate(tail) if b in (0xFD, 0xFE)):
            break
    layout.append({"offset": len(buf), "length": len(tail), "kind": "garbage", "error_bytes": len(tail)})
    buf += tail
    _, frame = some_frame("v2")
    cut = frame[:rng.randint(1, len(frame) - 1)]
    layout.append({"offset": len(buf), "length": len(cut), "kind": "truncated_at_eof", "error_bytes": len(cut)})
    buf += cut

    offsets = [r["offset"] for r in expected]
    check(rescan(buf, by_id) == offsets, "stream.bin: a rescanning parser does not find exactly the expected frames")
    mav = dialect.MAVLink(None)
    mav.robust_parsing = True
    mav.signing.secret_key = KEY
    mav.signing.allow_unsigned_callback = lambda _mav, _id: True
    got = [m for m in (mav.parse_buffer(bytes(buf)) or []) if m.get_type() != "BAD_DATA" and not m.get_type().startswith("UNKNOWN")]
    check([bytes(m.get_msgbuf()).hex() for m in got] == [r["frame"] for r in expected],
          "stream.bin: pymavlink's robust parser does not return exactly the expected frames")
    return bytes(buf), expected, layout


# ------------------------------------------------------------- benchmark input

# The mix of a copter's telemetry at its usual stream rates (the messages of
# the shared benchmark file, in the same numbers), in a seeded random order.
TELEMETRY_MIX = [("ATTITUDE", 33333), ("GLOBAL_POSITION_INT", 33333), ("VFR_HUD", 13334), ("SYS_STATUS", 6668),
                 ("BATTERY_STATUS", 3333), ("MISSION_ITEM_INT", 3333), ("HEARTBEAT", 3333), ("MISSION_CURRENT", 3333)]


def telemetry_mix():
    """100,000 MAVLink 2 frames of one copter (system 1, component 1), with
    plausible, varying values; checked by parsing them back with pymavlink."""
    rng = random.Random(SEED + 2)
    order = [name for name, n in TELEMETRY_MIX for _ in range(n)]
    rng.shuffle(order)
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    lat, lon, alt, t = -353632593, 1491652372, 584090, 123460
    wp = 0
    out = bytearray()

    def r(s):
        return rng.uniform(-s, s)

    for name in order:
        t += rng.randint(2, 5)
        lat += rng.randint(-30, 30)
        lon += rng.randint(-30, 30)
        alt = max(584000, alt + rng.randint(-60, 80))
        if name == "ATTITUDE":
            m = dialect.MAVLink_attitude_message(t, r(0.1), r(0.1), r(3.1), r(0.05), r(0.05), r(0.05))
        elif name == "GLOBAL_POSITION_INT":
            m = dialect.MAVLink_global_position_int_message(t, lat, lon, alt, alt - 584090, rng.randint(-600, 600),
                                                            rng.randint(-600, 600), rng.randint(-100, 100), rng.randint(0, 35999))
        elif name == "VFR_HUD":
            m = dialect.MAVLink_vfr_hud_message(rng.uniform(0, 12), rng.uniform(0, 12), rng.randint(0, 359), rng.randint(40, 70),
                                                alt / 1000.0, r(1.0))
        elif name == "SYS_STATUS":
            m = dialect.MAVLink_sys_status_message(325123119, 325123119, 325123087, rng.randint(200, 600), rng.randint(14800, 16800),
                                                   rng.randint(300, 3500), rng.randint(20, 100), 0, 0, 0, 0, 0, 0)
        elif name == "BATTERY_STATUS":
            cells = [rng.randint(3900, 4150) for _ in range(4)] + [65535] * 6
            m = dialect.MAVLink_battery_status_message(0, 0, 1, rng.randint(3400, 3600), cells, rng.randint(300, 3500),
                                                       rng.randint(0, 5000), -1, rng.randint(20, 100), rng.randint(0, 1800), 1)
        elif name == "MISSION_ITEM_INT":
            wp = wp % 49 + 1
            m = dialect.MAVLink_mission_item_int_message(255, 190, wp, 6, 16, 0, 1, 0.0, 2.0, 0.0, math.nan,
                                                         lat + rng.randint(-5000, 5000), lon + rng.randint(-5000, 5000), 20.0)
        elif name == "HEARTBEAT":
            m = dialect.MAVLink_heartbeat_message(2, 3, 217, rng.choice([0, 3, 5, 6]), 4, 3)
        else:
            m = dialect.MAVLink_mission_current_message(rng.randint(1, 49), 50, 3, 0)
        out += m.pack(mav)
        mav.seq = (mav.seq + 1) % 256
    check_mav = dialect.MAVLink(None)
    got = check_mav.parse_buffer(bytes(out)) or []
    check(len(got) == len(order) and [m.get_type() for m in got] == order, "telemetry mix: pymavlink does not read it back")
    return bytes(out)


# ------------------------------------------------------------- output

README = """# MAVLink test vectors of this project (generated: do not edit)

Made by `scripts/make_vectors.py` (run by `scripts/bootstrap`) with the
reference implementation, pymavlink {version}, for the dialect ardupilotmega
(XML in `priv/mavlink/`); seed {seed}, {k} instances per message. The JSON
conventions are those of the shared vectors
(`../shared/mavlink/vectors/README.md`, when present), in short:

| file | records | what |
| --- | --- | --- |
| `ardupilotmega.v2.jsonl` | {n_v2} | every message id x {k} instances, MAVLink 2, unsigned |
| `ardupilotmega.v1.jsonl` | {n_v1} | the same instances of every message with id < 256, MAVLink 1 (payload cut to the non-extension length, as the C library sends it) |
| `ardupilotmega.signed.jsonl` | {n_signed} | {signed_per} of the instances of every message, MAVLink 2, signed |
| `stream.bin` | {n_bytes} bytes | valid v1/v2/signed frames interleaved with garbage, truncated and corrupted frames |
| `stream.expected.jsonl` | {n_expected} | exactly the frames a correct parser returns from `stream.bin`, in order (plus `index` and `offset`) |
| `stream.layout.jsonl` | {n_layout} | what each byte range of `stream.bin` is |
| `crc_extra.json` | {n_messages} | per message id: name, CRC_EXTRA, min/max payload length |

A record: `msg id mavlink signed sysid compid seq fields frame` (+ `signing`
with `secret_key link_id timestamp` when signed, + `profile`: zero, max, min,
sparse or random). `fields` are the values pymavlink decodes from `frame`, in
XML order; floats as the shortest decimal that round-trips, NaN and infinities
as the strings "NaN", "Infinity", "-Infinity", negative zero as -0.0; `char[N]`
fields as strings up to the first NUL. Signing key: SHA-256 of
"mavlink-vectors/visible/signing-key" ({key}). Signed frames of the stream
have strictly increasing timestamps; the other signed records are to be
verified each with a fresh replay table.
"""


def write(path, data):
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def jsonl(records):
    return "".join(dumps(r) + "\n" for r in records).encode()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vectors", default=os.path.join(ROOT, "test", "vectors"), help="output directory of the vectors")
    parser.add_argument("--bench", default=os.path.join(ROOT, "bench", "data", "telemetry_mix.bin"), help="output file of the benchmark input")
    args = parser.parse_args()

    messages = load_dialect()
    v2, v1, signed = record_sets(messages)
    stream_bytes, expected, layout = stream(messages)
    bench = telemetry_mix()

    os.makedirs(args.vectors, exist_ok=True)
    os.makedirs(os.path.dirname(args.bench), exist_ok=True)
    write(os.path.join(args.vectors, "ardupilotmega.v2.jsonl"), jsonl(v2))
    write(os.path.join(args.vectors, "ardupilotmega.v1.jsonl"), jsonl(v1))
    write(os.path.join(args.vectors, "ardupilotmega.signed.jsonl"), jsonl(signed))
    write(os.path.join(args.vectors, "crc_extra.json"), (json.dumps(crc_table(messages), indent=1) + "\n").encode())
    write(os.path.join(args.vectors, "stream.bin"), stream_bytes)
    write(os.path.join(args.vectors, "stream.expected.jsonl"), jsonl(expected))
    write(os.path.join(args.vectors, "stream.layout.jsonl"), jsonl(layout))
    import pymavlink
    write(os.path.join(args.vectors, "README.md"), README.format(
        version=getattr(pymavlink, "__version__", "?"), seed=SEED, k=K, n_v2=len(v2), n_v1=len(v1), n_signed=len(signed),
        signed_per=SIGNED_PER_MESSAGE, n_bytes=len(stream_bytes), n_expected=len(expected), n_layout=len(layout),
        n_messages=len(messages), key=KEY.hex()).encode())
    write(args.bench, bench)
    print("make_vectors: %d messages; %d v2, %d v1, %d signed records; stream %d bytes, %d frames; bench %d bytes"
          % (len(messages), len(v2), len(v1), len(signed), len(stream_bytes), len(expected), len(bench)), file=sys.stderr)


if __name__ == "__main__":
    try:
        main()
    except Fail as e:
        sys.exit("make_vectors: %s" % e)
