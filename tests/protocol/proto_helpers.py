"""Helpers for the protocol tests: the golden vectors, and the firmware's C++ codec built for
the host (build/host/libutrf_proto.so, loaded with ctypes)."""

from __future__ import annotations

import ctypes
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from utrf.protocol.framing import MAX_BODY_BYTES, Frame, FrameError, RxEvent

REPO_ROOT = Path(__file__).resolve().parents[2]
VECTOR_DIR = REPO_ROOT / "protocol" / "vectors"
LIB_PATH = REPO_ROOT / "build" / "host" / "libutrf_proto.so"


def load_vectors(name: str) -> dict[str, Any]:
    return json.loads((VECTOR_DIR / name).read_text(encoding="utf-8"))


class RxRecord(ctypes.Structure):
    _fields_ = [
        ("event", ctypes.c_uint8),
        ("seq", ctypes.c_uint8),
        ("msg_id", ctypes.c_uint8),
        ("body_len", ctypes.c_uint8),
        ("body", ctypes.c_uint8 * MAX_BODY_BYTES),
    ]


@dataclass
class CppDecodeResult:
    status: int  # 0 OK, 1 BAD_LENGTH, 2 OUT_OF_RANGE, -1 unknown id
    bad_field: int
    values: list[float]
    reencoded: bytes


class CppCodec:
    """The firmware's framing.cpp and generated header, through tests/protocol/cpp/shim.cpp."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        u8p = ctypes.POINTER(ctypes.c_uint8)
        lib.utrf_crc16.argtypes = [ctypes.c_char_p, ctypes.c_uint16]
        lib.utrf_crc16.restype = ctypes.c_uint16
        lib.utrf_encode_frame.argtypes = [
            ctypes.c_uint8,
            ctypes.c_uint8,
            ctypes.c_char_p,
            ctypes.c_uint8,
            u8p,
        ]
        lib.utrf_encode_frame.restype = ctypes.c_uint8
        lib.utrf_max_frame_bytes.restype = ctypes.c_uint8
        lib.utrf_decoder_new.restype = ctypes.c_void_p
        lib.utrf_decoder_free.argtypes = [ctypes.c_void_p]
        lib.utrf_decoder_feed.argtypes = [
            ctypes.c_void_p,
            ctypes.c_char_p,
            ctypes.c_uint32,
            ctypes.POINTER(RxRecord),
            ctypes.c_uint32,
        ]
        lib.utrf_decoder_feed.restype = ctypes.c_int32
        lib.utrf_decoder_feed_runs.argtypes = lib.utrf_decoder_feed.argtypes
        lib.utrf_decoder_feed_runs.restype = ctypes.c_int32
        lib.utrf_message_size.argtypes = [ctypes.c_uint8]
        lib.utrf_message_size.restype = ctypes.c_int16
        lib.utrf_decode_message.argtypes = [
            ctypes.c_uint8,
            ctypes.c_char_p,
            ctypes.c_uint8,
            u8p,
            ctypes.POINTER(ctypes.c_double),
            u8p,
            u8p,
        ]
        lib.utrf_decode_message.restype = ctypes.c_int32
        lib.utrf_encode_message.argtypes = [ctypes.c_uint8, ctypes.POINTER(ctypes.c_double), u8p]
        lib.utrf_encode_message.restype = ctypes.c_int32
        lib.utrf_schema_hash.restype = ctypes.c_uint32
        lib.utrf_protocol_version.restype = ctypes.c_uint16
        self.lib = lib
        self.max_frame_bytes = lib.utrf_max_frame_bytes()

    def crc16(self, data: bytes) -> int:
        return self.lib.utrf_crc16(data, len(data))

    def encode_frame(self, seq: int, msg_id: int, body: bytes) -> bytes:
        out = (ctypes.c_uint8 * self.max_frame_bytes)()
        n = self.lib.utrf_encode_frame(seq, msg_id, body, len(body), out)
        return bytes(out[:n])

    def decode_stream(
        self, data: bytes, chunks: list[int] | None = None, runs: bool = False
    ) -> list[Frame | FrameError]:
        """Every event of one fresh decoder fed ``data`` (in ``chunks`` of these sizes), a
        byte at a time, or with ``runs`` as the firmware's receive loop feeds it (feed_run)."""
        feed = self.lib.utrf_decoder_feed_runs if runs else self.lib.utrf_decoder_feed
        decoder = self.lib.utrf_decoder_new()
        try:
            events: list[Frame | FrameError] = []
            pieces = [data] if not chunks else _split(data, chunks)
            for piece in pieces:
                records = (RxRecord * (len(piece) + 1))()
                n = feed(decoder, piece, len(piece), records, len(records))
                assert n >= 0
                for r in records[:n]:
                    kind = RxEvent(r.event)
                    if kind is RxEvent.FRAME:
                        events.append(Frame(r.seq, r.msg_id, bytes(r.body[: r.body_len])))
                    elif kind is RxEvent.CRC_ERROR:
                        events.append(FrameError(kind, r.seq, r.msg_id))
                    else:
                        events.append(FrameError(kind))
            return events
        finally:
            self.lib.utrf_decoder_free(decoder)

    def message_size(self, msg_id: int) -> int:
        return self.lib.utrf_message_size(msg_id)

    def decode_message(self, msg_id: int, body: bytes) -> CppDecodeResult:
        bad = ctypes.c_uint8(0xEE)
        values = (ctypes.c_double * MAX_BODY_BYTES)()
        n = ctypes.c_uint8(0)
        out = (ctypes.c_uint8 * MAX_BODY_BYTES)()
        status = self.lib.utrf_decode_message(
            msg_id, body, len(body), ctypes.byref(bad), values, ctypes.byref(n), out
        )
        size = max(self.message_size(msg_id), 0)
        return CppDecodeResult(
            status, bad.value, list(values[: n.value]), bytes(out[:size]) if status == 0 else b""
        )

    def encode_message(self, msg_id: int, values: list[float]) -> bytes:
        arr = (ctypes.c_double * MAX_BODY_BYTES)(*values)
        out = (ctypes.c_uint8 * MAX_BODY_BYTES)()
        n = self.lib.utrf_encode_message(msg_id, arr, out)
        assert n >= 0, f"unknown id {msg_id}"
        return bytes(out[:n])


def _split(data: bytes, chunks: list[int]) -> list[bytes]:
    pieces, pos = [], 0
    for size in chunks:
        if pos >= len(data):
            break
        pieces.append(data[pos : pos + size])
        pos += size
    if pos < len(data):
        pieces.append(data[pos:])
    return [p for p in pieces if p]


def events_json(events: list[Frame | FrameError]) -> list[dict[str, Any]]:
    """Events in the vectors' JSON form."""
    out: list[dict[str, Any]] = []
    for e in events:
        if isinstance(e, Frame):
            out.append({"event": "frame", "seq": e.seq, "msg_id": e.msg_id, "body": e.body.hex()})
        elif e.kind is RxEvent.CRC_ERROR:
            out.append({"event": "crc_error", "seq": e.seq, "msg_id": e.msg_id})
        else:
            out.append({"event": e.kind.name.lower()})
    return out
