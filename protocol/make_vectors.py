"""Write the golden vectors in protocol/vectors/ from the spec and the Python codec.

    python -m protocol.make_vectors            # write messages.json and streams.json
    python -m protocol.make_vectors --check    # exit 1 and name the files that are stale

messages.json: for every message, frames with their decoded meaning (SI and raw), and bodies
that must be refused (bad length, each checked field out of range) with the field to blame.
streams.json: byte streams (garbage, truncated, oversized, dropped bytes, bit flips,
interleaved garbage) with exactly the events a receiver must deliver. Each stream's events are
written down here from how it was built, and the codec must agree before anything is
written, so the file is not merely the codec's own output. handmade.json (CRC and COBS
examples and frames derived by hand) is kept by hand and never written by this script.
Run it with the project's Python (.venv/bin/python): it needs the utrf package.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import struct
import sys
import zlib
from enum import IntEnum, IntFlag
from pathlib import Path
from typing import Any

from tools.generated import write_or_check
from utrf.protocol import messages as M
from utrf.protocol.codec import WIRE_TYPES, Field, Message, Request, to_f32
from utrf.protocol.framing import (
    MAX_ENCODED_BYTES,
    Frame,
    FrameDecoder,
    FrameError,
    RxEvent,
    encode_frame,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
VECTOR_DIR = REPO_ROOT / "protocol" / "vectors"


# --------------------------------------------------------------------------------------------
# Values <-> JSON
# --------------------------------------------------------------------------------------------


def si_json(value: Any) -> Any:
    """A field value for JSON: enum members by name, flags as a list of names."""
    if isinstance(value, tuple):
        return [si_json(v) for v in value]
    if isinstance(value, IntFlag):
        return [m.name for m in type(value) if m in value]
    if isinstance(value, IntEnum):
        return value.name
    return value


def raw_json(raw: dict[str, Any]) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in raw.items()}


def pack_raw(cls: type[Message], raw: dict[str, Any]) -> bytes:
    """Pack raw values with no checks at all (to build invalid bodies)."""
    flat: list[Any] = []
    for f in cls.FIELDS:
        value = raw[f.name]
        flat.extend(value if f.count is not None else [value])
    return cls._STRUCT.pack(*flat)


# --------------------------------------------------------------------------------------------
# Message vectors
# --------------------------------------------------------------------------------------------


def _raw_choice(f: Field, rng: random.Random, how: str) -> int | float:
    if f.enum is not None:
        values = sorted(int(m) for m in f.enum)
        return {"low": values[0], "high": values[-1]}.get(how, rng.choice(values))
    if f.flags is not None:
        bits = [int(m) for m in f.flags]
        if how == "low":
            return 0
        if how == "high":
            return sum(bits)
        return sum(b for b in bits if rng.random() < 0.4)
    if f.type == "f32":
        lo = -1000.0 if f.min is None else f.min
        hi = 1000.0 if f.max is None else f.max
        if how == "low":
            return lo
        if how == "high":
            return hi
        return to_f32(rng.uniform(lo, hi))
    lo, hi = int(f._lo), int(f._hi)
    return {"low": lo, "high": hi}.get(how, rng.randint(lo, hi))


def example_raw(cls: type[Message], how: str) -> dict[str, Any]:
    rng = random.Random(zlib.crc32(f"{cls.NAME}/{how}".encode()))
    raw: dict[str, Any] = {}
    for f in cls.FIELDS:
        if f.count is None:
            raw[f.name] = _raw_choice(f, rng, how)
        else:
            raw[f.name] = tuple(_raw_choice(f, rng, how) for _ in range(f.count))
    return raw


def seq_for(cls: type[Message], n: int) -> int:
    """Requests and replies use seqs without the board flag; stream messages with it."""
    if cls in (M.State, M.Status, M.Fault, M.Boot) and n % 2 == 0:
        return M.BOARD_SEQ_FLAG | (n * 37 % 128)
    return n * 37 % 128


def message_vectors() -> list[dict[str, Any]]:
    out = []
    n = 0
    for cls in M.MESSAGES:
        for how in ("typical", "low", "high"):
            raw = example_raw(cls, how)
            msg = cls.from_raw(raw)
            body = msg.encode()
            assert cls.decode(body) == msg
            seq = seq_for(cls, n)
            n += 1
            out.append(
                {
                    "name": cls.NAME,
                    "id": cls.ID,
                    "case": how,
                    "seq": seq,
                    "fields": {f.name: si_json(getattr(msg, f.name)) for f in cls.FIELDS},
                    "raw": raw_json(msg.to_raw()),
                    "body": body.hex(),
                    "frame": encode_frame(seq, cls.ID, body).hex(),
                }
            )
    return out


def _invalid_raws(f: Field) -> list[tuple[str, int | float]]:
    """(description, raw) pairs that the field must refuse."""
    code, type_lo, type_hi = WIRE_TYPES[f.type]
    cases: list[tuple[str, int | float]] = []
    if f.enum is not None:
        values = {int(m) for m in f.enum}
        bad = next(v for v in range(int(type_hi) + 1) if v not in values)
        cases.append((f"{bad} is not a {f.enum.__name__}", bad))
    elif f.flags is not None:
        all_bits = sum(int(m) for m in f.flags)
        spare = [1 << b for b in range(8 * struct.calcsize(code)) if not all_bits & (1 << b)]
        if spare:
            cases.append((f"undefined bit 0x{spare[0]:02X}", spare[0]))
    elif f.type == "f32":
        cases.append(("NaN", math.nan))
        cases.append(("+infinity", math.inf))
        if f.min is not None:
            below = to_f32(math.nextafter(f.min, -math.inf) if f.min else -1e-30)
            while below >= f.min:
                below = to_f32(below - abs(below) * 1e-6 - 1e-30)
            cases.append(("just below min", below))
        if f.max is not None:
            above = to_f32(math.nextafter(f.max, math.inf))
            while above <= f.max:
                above = to_f32(above + abs(above) * 1e-6 + 1e-30)
            cases.append(("just above max", above))
    else:
        if f._lo > type_lo:
            cases.append(("one below min", int(f._lo) - 1))
        if f._hi < type_hi:
            cases.append(("one above max", int(f._hi) + 1))
    return cases


def invalid_vectors() -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for cls in M.MESSAGES:
        good = pack_raw(cls, example_raw(cls, "typical"))
        out.append(
            {
                "name": cls.NAME,
                "id": cls.ID,
                "case": "one byte too many",
                "body": (good + b"\x00").hex(),
                "error": "bad_length",
            }
        )
        if good:
            out.append(
                {
                    "name": cls.NAME,
                    "id": cls.ID,
                    "case": "one byte short",
                    "body": good[:-1].hex(),
                    "error": "bad_length",
                }
            )
        for f in cls.FIELDS:
            for what, bad in _invalid_raws(f):
                raw = example_raw(cls, "typical")
                if f.count is None:
                    raw[f.name] = bad
                    label = f.name
                else:
                    # the last element, so every earlier one is checked and valid first
                    raw[f.name] = (*raw[f.name][:-1], bad)
                    label = f"{f.name}[{f.count - 1}]"
                out.append(
                    {
                        "name": cls.NAME,
                        "id": cls.ID,
                        "case": f"{label}: {what}",
                        "body": pack_raw(cls, raw).hex(),
                        "error": "out_of_range",
                        "field": f.name,
                        "field_index": f.index,
                    }
                )
    return out


# --------------------------------------------------------------------------------------------
# Stream vectors
# --------------------------------------------------------------------------------------------


def frame_event(seq: int, msg: Message) -> dict[str, Any]:
    return {"event": "frame", "seq": seq, "msg_id": msg.ID, "body": msg.encode().hex()}


def ev(kind: str, seq: int | None = None, msg_id: int | None = None) -> dict[str, Any]:
    e: dict[str, Any] = {"event": kind}
    if seq is not None:
        e["seq"] = seq
        e["msg_id"] = msg_id
    return e


def events_json(events: list[Frame | FrameError]) -> list[dict[str, Any]]:
    out = []
    for e in events:
        if isinstance(e, Frame):
            out.append({"event": "frame", "seq": e.seq, "msg_id": e.msg_id, "body": e.body.hex()})
        elif e.kind is RxEvent.CRC_ERROR:
            out.append(ev("crc_error", e.seq, e.msg_id))
        else:
            out.append(ev(e.kind.name.lower()))
    return out


#: The framing vectors use frames of the largest size (a 64-byte body). No message is that
#: large, and the framing never looks at the id: 0x7F is no message's.
BIG_ID = 0x7F


def _big_body(t: float) -> bytes:
    """64 bytes with the zeros and the spread of a busy telemetry frame (the protocol's
    first state layout, kept so the hand-checked byte positions below stay put)."""
    return struct.pack(
        "<I5h5h5b5b5B5B5h5h",
        round(t * 1e6),
        *(1000, 2500, -500, 5000, 12000),
        *(1000, 3000, 0, 5000, 12500),
        *(12, 50, -20, 0, 100),
        *(5, 0, 30, 0, -100),
        *(2, 2, 2, 2, 4),
        *(0, 0, 0, 0, 4),
        *(8000, 9000, 9500, 9000, 7000),
        *(1000, 2000, 0, 3000, 6000),
    )


def big_event(seq: int, body: bytes) -> dict[str, Any]:
    return {"event": "frame", "seq": seq, "msg_id": BIG_ID, "body": body.hex()}


def stream_vectors() -> list[dict[str, Any]]:
    ping = M.Ping(token=0x00C0FFEE)
    targets = M.SetTargets(
        kind=M.TargetKind.JOINT2_ANGLE, mask=0x1F, value=(0.5, 0.0, -0.25, 1.0, 0.0)
    )
    ack = M.Ack(msg_id=M.SetTargets.ID)
    hb = M.Heartbeat()
    s1, s2, s3 = _big_body(1.0), _big_body(1.002), _big_body(1.004)
    fp = encode_frame(0x01, ping.ID, ping.encode())
    ft = encode_frame(0x02, targets.ID, targets.encode())
    fa = encode_frame(0x02, ack.ID, ack.encode())
    fh = encode_frame(0x03, hb.ID, hb.encode())
    f1 = encode_frame(0x80, BIG_ID, s1)
    f2 = encode_frame(0x81, BIG_ID, s2)
    f3 = encode_frame(0x82, BIG_ID, s3)
    e_p, e_t, e_a, e_h = (
        frame_event(1, ping),
        frame_event(2, targets),
        frame_event(2, ack),
        frame_event(3, hb),
    )
    e1, e2, e3 = big_event(0x80, s1), big_event(0x81, s2), big_event(0x82, s3)
    assert len(f1) == MAX_ENCODED_BYTES + 1, "a 64-byte body makes a frame of the largest size"

    def flip(frame: bytes, i: int, bit: int) -> bytes:
        b = bytearray(frame)
        b[i] ^= 1 << bit
        return bytes(b)

    # A bit flip inside the state frame's body: a CRC error that still names seq and id.
    f2_flipped = flip(f2, 10, 3)
    assert 0 not in f2_flipped[:-1]
    # A flip of seq's byte (index 1: after the COBS code byte).
    fp_seq_flipped = flip(fp, 1, 1)
    garbage = bytes(random.Random(7).randrange(1, 256) for _ in range(23))
    long_garbage = bytes(random.Random(8).randrange(1, 256) for _ in range(150))

    cases: list[tuple[str, str, bytes, list[dict[str, Any]]]] = [
        ("clean", "frames back to back", fp + ft + fa + f1, [e_p, e_t, e_a, e1]),
        (
            "spare_delimiters",
            "empty frames (repeated 0x00) are ignored",
            b"\x00\x00" + fp + b"\x00\x00\x00" + fh + b"\x00",
            [e_p, e_h],
        ),
        (
            "largest_frame",
            "a 64-byte body: 69 COBS bytes and the 0x00, the most a frame holds",
            f1 + f2,
            [e1, e2],
        ),
        (
            "garbage_then_delimiter",
            "garbage ended by 0x00 is one bad frame; the next is intact",
            garbage + b"\x00" + fp,
            [ev("framing_error"), e_p],
        ),
        (
            "garbage_glued_to_frame",
            "garbage with no 0x00 joins the next frame, which is lost; the one after is intact",
            garbage + fp + ft,
            [ev("framing_error"), e_t],
        ),
        (
            "interleaved_garbage",
            "garbage between frames, each piece ended by 0x00",
            fp
            + garbage[:5]
            + b"\x00"
            + ft
            + garbage[5:9]
            + b"\x00"
            + b"\x00"
            + fa
            + b"\x07\x00"
            + f1,
            [e_p, ev("framing_error"), e_t, ev("framing_error"), e_a, ev("framing_error"), e1],
        ),
        (
            "truncated_mid_block",
            "a frame cut inside a COBS block, then 0x00 (a sender reset)",
            f1[:28] + b"\x00" + f2,
            [ev("framing_error"), e2],
        ),
        (
            "truncated_at_block_end",
            "a frame cut where a COBS block ends decodes, then fails its CRC",
            f1[:30] + b"\x00" + f2,
            [ev("crc_error", 0x80, BIG_ID), e2],
        ),
        (
            "truncated_glued",
            "the first half of a frame runs into the next: both lost",
            f1[:30] + f2 + f3,
            [ev("oversize"), e3],
        ),
        (
            "oversize_then_delimiter",
            "150 bytes with no 0x00: reported once, dropped to the 0x00",
            long_garbage + b"\x00" + fp,
            [ev("oversize"), e_p],
        ),
        (
            "oversize_glued",
            "an oversized run swallows the frame it runs into; then resync",
            long_garbage + fp + ft,
            [ev("oversize"), e_t],
        ),
        (
            "one_byte_too_long",
            "70 COBS bytes before the 0x00: one more than any frame",
            bytes([0x46]) + bytes(range(1, 70)) + b"\x00" + fh,
            [ev("oversize"), e_h],
        ),
        (
            "dropped_byte_last_block",
            "a byte of the last COBS block dropped: its code overruns",
            f1[:65] + f1[66:] + f2,
            [ev("framing_error"), e2],
        ),
        (
            "dropped_byte_mid_frame",
            "a body byte dropped mid-frame: blocks still line up, CRC fails",
            f1[:40] + f1[41:] + f2,
            [ev("crc_error", 0x80, BIG_ID), e2],
        ),
        (
            "dropped_delimiter",
            "a lost 0x00 merges two frames into an oversized one",
            f1[:-1] + f2 + f3,
            [ev("oversize"), e3],
        ),
        (
            "dropped_delimiter_short",
            "a lost 0x00 between two short frames: one CRC error",
            fp[:-1] + fh + ft,
            [ev("crc_error", 0x01, ping.ID), e_t],
        ),
        (
            "bit_flip_body",
            "a flipped bit in the body: CRC error, seq and id still readable",
            fp + f2_flipped + f3,
            [e_p, ev("crc_error", 0x81, BIG_ID), e3],
        ),
        (
            "bit_flip_seq",
            "a flipped bit in seq: CRC error naming the damaged seq (a hint only)",
            fp_seq_flipped + ft,
            [ev("crc_error", 0x03, ping.ID), e_t],
        ),
        (
            "bit_flip_to_zero",
            "a byte hit to 0x00 splits a frame into two bad pieces",
            f1[:20] + b"\x00" + f1[21:] + fp,
            [ev("framing_error"), ev("crc_error", 0x00, f1[23]), e_p],
        ),
        (
            "too_short",
            "a COBS frame of 3 bytes: shorter than seq, id and CRC",
            bytes([0x04, 0x01, 0x02, 0x03, 0x00]) + fp,
            [ev("framing_error"), e_p],
        ),
        (
            "unknown_id_and_bad_length",
            "framing does not judge bodies: an unknown id and a short body are delivered as frames",
            encode_frame(9, 0x7E, b"\x01\x02") + encode_frame(10, M.Ping.ID, b"\x01"),
            [
                {"event": "frame", "seq": 9, "msg_id": 0x7E, "body": "0102"},
                {"event": "frame", "seq": 10, "msg_id": M.Ping.ID, "body": "01"},
            ],
        ),
        ("unterminated", "a frame without its 0x00 is not delivered (yet)", fp + ft[:-1], [e_p]),
    ]
    out = []
    for name, description, data, expect in cases:
        got = events_json(FrameDecoder().feed(data))
        if got != expect:
            raise AssertionError(f"stream {name}: the codec delivers {got}, expected {expect}")
        # Byte by byte must deliver exactly the same events.
        dec = FrameDecoder()
        one_by_one = [e for i in range(len(data)) for e in dec.feed(data[i : i + 1])]
        if events_json(one_by_one) != expect:
            raise AssertionError(f"stream {name}: byte-by-byte feeding differs")
        out.append(
            {"name": name, "description": description, "bytes": data.hex(), "expect": expect}
        )
    return out


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


def header() -> dict[str, Any]:
    return {
        "generated_by": "protocol/make_vectors.py (do not edit)",
        "protocol_version": M.PROTOCOL_VERSION,
        "schema_hash": f"0x{M.SCHEMA_HASH:08X}",
    }


def render() -> dict[Path, str]:
    messages = {
        **header(),
        "about": "frame = hex of the whole frame with its 0x00; body = the message body; fields "
        "are SI (enums by name, flags as lists of names), raw the wire integers. invalid: bodies "
        "decode must refuse, with field_index = the nack detail for out_of_range.",
        "messages": message_vectors(),
        "invalid": invalid_vectors(),
        "requests": {
            cls.NAME: {
                "reply": cls.REPLY.NAME,
                "idempotent": cls.IDEMPOTENT,
                "reply_timeout_s": cls.REPLY_TIMEOUT_S,
            }
            for cls in M.MESSAGES
            if issubclass(cls, Request)
        },
    }
    streams = {
        **header(),
        "about": "bytes = what arrives on the line; expect = every event a fresh receiver "
        "reports, in order (frame: seq, msg_id, body; crc_error: the seq and msg_id as "
        "received; framing_error; oversize).",
        "streams": stream_vectors(),
    }
    return {
        VECTOR_DIR / "messages.json": json.dumps(messages, indent=1) + "\n",
        VECTOR_DIR / "streams.json": json.dumps(streams, indent=1) + "\n",
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a vector file is stale")
    args = parser.parse_args(argv)
    return write_or_check(
        render(),
        check=args.check,
        tool="make_vectors",
        command=".venv/bin/python -m protocol.make_vectors",
        root=REPO_ROOT,
    )


if __name__ == "__main__":
    sys.exit(main())
