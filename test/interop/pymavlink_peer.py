#!/usr/bin/env python3
"""pymavlink as a live interop peer for test/interop/pymavlink_test.exs.

Subcommands (JSON records as in test/vectors/README.md, made by scripts/make_vectors.py; one a line):

  generate --seed S --count N [--key HEX]
      N random messages of the ardupilotmega dialect, encoded by pymavlink
      itself: MAVLink 2 unsigned, MAVLink 2 signed and MAVLink 1 (ids < 256,
      sent with pymavlink's force_mavlink1, i.e. the full max_len payload
      including extension bytes). Every message of the dialect comes at least
      once when N >= 301. `frame` is the hex of what pymavlink produced;
      `fields` is what a fresh pymavlink parser decodes back from those bytes.

  decode [--key HEX]
      Hex frames on stdin, one a line; for each, one record (without `frame`)
      as a fresh pymavlink parser decodes it (CRC checked; the signature
      checked with the key when the frame is signed and a key is given), or
      {"error": "..."} when pymavlink rejects the frame.

Only the standard library and pymavlink are used.
"""

import argparse
import inspect
import json
import math
import random
import struct
import sys

from pymavlink.dialects.v20 import ardupilotmega as mavlink

# Never let MAV_IGNORE_CRC in the environment switch the CRC check off.
mavlink.MAVLINK_IGNORE_CRC = 0

DEFAULT_KEY = bytes.fromhex("6c9a1f0e5b3d2c4a8f7e6d5c4b3a29181f2e3d4c5b6a79880f1e2d3c4b5a6978")

INT_RANGES = {
    "uint8_t": (0, 0xFF),
    "int8_t": (-0x80, 0x7F),
    "uint16_t": (0, 0xFFFF),
    "int16_t": (-0x8000, 0x7FFF),
    "uint32_t": (0, 0xFFFFFFFF),
    "int32_t": (-0x80000000, 0x7FFFFFFF),
    "uint64_t": (0, 0xFFFFFFFFFFFFFFFF),
    "int64_t": (-0x8000000000000000, 0x7FFFFFFFFFFFFFFF),
}

FLT_MAX = struct.unpack("<f", struct.pack("<I", 0x7F7FFFFF))[0]
FLT_MIN = struct.unpack("<f", struct.pack("<I", 0x00800000))[0]  # smallest normal
FLT_TRUE_MIN = struct.unpack("<f", struct.pack("<I", 0x00000001))[0]  # smallest subnormal
FLT_SUB_MAX = struct.unpack("<f", struct.pack("<I", 0x007FFFFF))[0]  # largest subnormal
DBL_MAX = struct.unpack("<d", struct.pack("<Q", 0x7FEFFFFFFFFFFFFF))[0]
DBL_TRUE_MIN = struct.unpack("<d", struct.pack("<Q", 1))[0]
DBL_SUB_MAX = struct.unpack("<d", struct.pack("<Q", 0x000FFFFFFFFFFFFF))[0]
INF = float("inf")
NAN = struct.unpack("<d", struct.pack("<Q", 0x7FF8000000000000))[0]  # canonical quiet NaN

FLOAT_EDGES = [0.0, -0.0, NAN, INF, -INF, FLT_MAX, -FLT_MAX, FLT_MIN, -FLT_MIN,
               FLT_TRUE_MIN, -FLT_TRUE_MIN, FLT_SUB_MAX, -FLT_SUB_MAX, 1.0, -1.0]
DOUBLE_EDGES = [0.0, -0.0, NAN, INF, -INF, DBL_MAX, -DBL_MAX, DBL_TRUE_MIN, -DBL_TRUE_MIN,
                DBL_SUB_MAX, -DBL_SUB_MAX, FLT_MAX, FLT_TRUE_MIN, 1.0, -1.0]

PRINTABLE = bytes(range(0x20, 0x7F))


def message_classes():
    return [mavlink.mavlink_map[i] for i in sorted(mavlink.mavlink_map)]


def field_specs(cls):
    """[(name, type, array_length or 0, is_extension)] in XML order."""
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    params = inspect.signature(cls.__init__).parameters
    return [
        (name, ftype, lengths[name], params[name].default is not inspect.Parameter.empty)
        for name, ftype in zip(cls.fieldnames, cls.fieldtypes)
    ]


# ---------------------------------------------------------------- random values

def random_float32(rng):
    """A random finite float32 value (as a Python float), over all magnitudes."""
    while True:
        bits = rng.getrandbits(32)
        if (bits >> 23) & 0xFF != 0xFF:
            return struct.unpack("<f", struct.pack("<I", bits))[0]


def random_float64(rng):
    while True:
        bits = rng.getrandbits(64)
        if (bits >> 52) & 0x7FF != 0x7FF:
            return struct.unpack("<d", struct.pack("<Q", bits))[0]


def scalar_value(rng, ftype, profile):
    if ftype in INT_RANGES:
        lo, hi = INT_RANGES[ftype]
        if profile == "zero":
            return 0
        if profile == "max":
            return hi
        if profile == "min":
            return lo
        r = rng.random()
        if r < 0.2:
            return rng.choice([lo, hi, 0, 1, hi - 1, lo + 1, -1 if lo < 0 else 2])
        if r < 0.4:
            return rng.randint(max(lo, -1000), min(hi, 1000))
        return rng.randint(lo, hi)
    if ftype in ("float", "double"):
        single = ftype == "float"
        if profile == "zero":
            return 0.0
        if profile == "max":
            return rng.choice([FLT_MAX, INF, NAN, 1e38] if single else [DBL_MAX, INF, NAN, 1e308])
        if profile == "min":
            return rng.choice([-FLT_MAX, -INF, -FLT_TRUE_MIN, -0.0] if single else [-DBL_MAX, -INF, -DBL_TRUE_MIN, -0.0])
        r = rng.random()
        if r < 0.25:
            return rng.choice(FLOAT_EDGES if single else DOUBLE_EDGES)
        if r < 0.5:
            return rng.uniform(-1000.0, 1000.0)  # float32-rounded by the encoder
        return random_float32(rng) if single else random_float64(rng)
    raise ValueError("unexpected field type %r" % ftype)


def string_value(rng, n, profile):
    if profile == "zero":
        return b""
    if profile in ("max", "min"):
        length = n
    else:
        length = rng.choice([0, n, rng.randint(0, n)])
    return bytes(rng.choice(PRINTABLE) for _ in range(length))


def field_value(rng, ftype, n, profile):
    if ftype == "char":
        return string_value(rng, n, profile)
    if n:
        values = [scalar_value(rng, ftype, profile) for _ in range(n)]
        if profile == "sparse" and rng.random() < 0.5:
            cut = rng.randint(0, n)
            zero = 0.0 if ftype in ("float", "double") else 0
            values = values[:cut] + [zero] * (n - cut)
        return values
    return scalar_value(rng, ftype, profile)


def random_fields(rng, cls, profile):
    values = {}
    for name, ftype, n, _ext in field_specs(cls):
        p = profile
        if profile == "sparse":
            if rng.random() < 0.5:
                p = "zero"
            else:
                p = "random"
        values[name] = field_value(rng, ftype, n, p)
    return values


# ---------------------------------------------------------------- records

def json_float(v):
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "Infinity" if v > 0 else "-Infinity"
    return v


def json_value(v):
    if isinstance(v, float):
        return json_float(v)
    if isinstance(v, (list, tuple)):
        return [json_value(x) for x in v]
    if isinstance(v, (bytes, bytearray)):
        return bytes(v).decode("ascii", errors="backslashreplace")
    return v


def message_fields(msg):
    """The fields of a decoded pymavlink message in XML order, JSON-ready."""
    return {name: json_value(getattr(msg, name)) for name in type(msg).fieldnames}


def parse_frame(frame, key):
    """Parses one frame with a fresh pymavlink parser; returns the message or raises."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = False
    signed = frame[0] == mavlink.PROTOCOL_MARKER_V2 and len(frame) > 2 and frame[2] & mavlink.MAVLINK_IFLAG_SIGNED
    if signed and key is not None:
        mav.signing.secret_key = key
    msgs = mav.parse_buffer(bytearray(frame))
    if not msgs:
        raise mavlink.MAVError("no message (frame incomplete?)")
    if len(msgs) != 1:
        raise mavlink.MAVError("%d messages in one frame" % len(msgs))
    msg = msgs[0]
    if isinstance(msg, (mavlink.MAVLink_bad_data, mavlink.MAVLink_unknown)):
        raise mavlink.MAVError("%s: %s" % (msg.get_type(), getattr(msg, "reason", "unknown message id")))
    if mav.buf_len() != 0:
        raise mavlink.MAVError("%d bytes left over after the frame" % mav.buf_len())
    if signed and key is not None and not msg.get_signed():
        raise mavlink.MAVError("signature not verified")
    return msg


def record(msg, frame, key):
    header = msg.get_header()
    signed = bool(frame[0] == mavlink.PROTOCOL_MARKER_V2 and frame[2] & mavlink.MAVLINK_IFLAG_SIGNED)
    rec = {
        "msg": msg.get_type(),
        "id": msg.get_msgId(),
        "mavlink": 2 if frame[0] == mavlink.PROTOCOL_MARKER_V2 else 1,
        "signed": signed,
        "sysid": header.srcSystem,
        "compid": header.srcComponent,
        "seq": header.seq,
        "fields": message_fields(msg),
    }
    if signed:
        link_id = frame[-13]
        timestamp = int.from_bytes(frame[-12:-6], "little")
        signing = {"link_id": link_id, "timestamp": timestamp}
        if key is not None:
            signing = {"secret_key": key.hex(), **signing}
        rec["signing"] = signing
    return rec


def dump(obj):
    sys.stdout.write(json.dumps(obj, allow_nan=False, separators=(",", ":")) + "\n")


# ---------------------------------------------------------------- subcommands

def generate(seed, count, key):
    rng = random.Random(seed)
    classes = message_classes()
    # Every message at least once, then random ones.
    order = list(classes)
    rng.shuffle(order)
    while len(order) < count:
        order.append(rng.choice(classes))
    for i in range(count):
        cls = order[i]
        profile = rng.choice(["zero", "max", "min", "sparse", "random", "random", "random"])
        fields = random_fields(rng, cls, profile)
        msg = cls(**fields)

        r = rng.random()
        if r < 0.25 and cls.id < 256:
            mode = "v1"
        elif r < 0.5:
            mode = "signed"
        else:
            mode = "v2"

        mav = mavlink.MAVLink(None, srcSystem=rng.randint(0, 255), srcComponent=rng.randint(0, 255))
        mav.seq = rng.randint(0, 255)
        if mode == "signed":
            mav.signing.secret_key = key
            mav.signing.link_id = rng.randint(0, 255)
            mav.signing.timestamp = rng.choice([0, 1, 2**48 - 2, rng.randint(0, 2**48 - 2)])
            mav.signing.sign_outgoing = True
        timestamp = mav.signing.timestamp
        link_id = mav.signing.link_id
        frame = msg.pack(mav, force_mavlink1=(mode == "v1"))

        decoded = parse_frame(frame, key)  # raises when pymavlink rejects its own frame
        rec = record(decoded, frame, key)
        if rec["msg"] != cls.msgname:
            raise SystemExit("pymavlink decoded %s from a %s frame" % (rec["msg"], cls.msgname))
        if mode == "signed":
            assert rec["signing"]["timestamp"] == timestamp and rec["signing"]["link_id"] == link_id
        rec["frame"] = frame.hex()
        rec["profile"] = profile
        dump(rec)


def decode(key):
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        try:
            frame = bytes.fromhex(line)
            msg = parse_frame(frame, key)
            dump(record(msg, frame, key))
        except (mavlink.MAVError, ValueError, IndexError, struct.error) as e:
            dump({"error": "%s: %s" % (type(e).__name__, getattr(e, "message", None) or str(e))})
    sys.stdout.flush()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("generate")
    g.add_argument("--seed", type=int, required=True)
    g.add_argument("--count", type=int, required=True)
    g.add_argument("--key", help="signing key, 64 hex digits (default: a fixed test key)")
    d = sub.add_parser("decode")
    d.add_argument("--key", help="signing key, 64 hex digits, to verify signed frames")
    args = ap.parse_args()

    key = bytes.fromhex(args.key) if args.key else None
    if key is not None and len(key) != 32:
        ap.error("--key must be 32 bytes (64 hex digits)")
    if args.cmd == "generate":
        generate(args.seed, args.count, key or DEFAULT_KEY)
    else:
        decode(key)


if __name__ == "__main__":
    main()
