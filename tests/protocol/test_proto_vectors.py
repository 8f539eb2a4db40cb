"""Both codecs, the Python one and the firmware's C++ one, against the golden vectors."""

from __future__ import annotations

import math
from enum import IntEnum, IntFlag
from typing import Any

import pytest
from cobs import cobs
from proto_helpers import CppCodec, events_json, load_vectors

from utrf.protocol import messages as M
from utrf.protocol.codec import Message
from utrf.protocol.errors import DecodeError
from utrf.protocol.framing import Frame, crc16_ccitt, decode_stream, encode_frame

MESSAGES = load_vectors("messages.json")
STREAMS = load_vectors("streams.json")
HANDMADE = load_vectors("handmade.json")


def _id(v: dict[str, Any]) -> str:
    return f"{v['name']}-{v.get('case', '')}"


def si_json(value: Any) -> Any:
    if isinstance(value, tuple):
        return [si_json(v) for v in value]
    if isinstance(value, IntFlag):
        return [m.name for m in type(value) if m in value]
    if isinstance(value, IntEnum):
        return value.name
    return value


def flat_raw(cls: type[Message], raw: dict[str, Any]) -> list[float]:
    out: list[float] = []
    for f in cls.FIELDS:
        value = raw[f.name]
        out.extend(value if isinstance(value, list) else [value])
    return out


def test_vectors_cover_every_message_with_this_spec() -> None:
    assert MESSAGES["schema_hash"] == f"0x{M.SCHEMA_HASH:08X}"
    assert STREAMS["schema_hash"] == f"0x{M.SCHEMA_HASH:08X}"
    assert {v["name"] for v in MESSAGES["messages"]} == set(M.BY_NAME)
    checked = {f"{v['name']}.{v['field']}" for v in MESSAGES["invalid"] if "field" in v}
    for cls in M.MESSAGES:
        for f in cls.FIELDS:
            bounds = (f.enum, f.flags, f.raw_min, f.raw_max)
            if f.type == "f32" or any(b is not None for b in bounds):  # a raw bound may be 0
                assert f"{cls.NAME}.{f.name}" in checked, (
                    f"no invalid vector for {cls.NAME}.{f.name}"
                )


# --- messages -----------------------------------------------------------------------------


@pytest.mark.parametrize("vec", MESSAGES["messages"], ids=_id)
def test_python_codec_matches_message_vector(vec: dict[str, Any]) -> None:
    cls = M.BY_NAME[vec["name"]]
    body = bytes.fromhex(vec["body"])
    assert vec["id"] == cls.ID
    (frame,) = decode_stream(bytes.fromhex(vec["frame"]))
    assert frame == Frame(vec["seq"], cls.ID, body)
    msg = cls.decode(body)
    assert {f.name: si_json(getattr(msg, f.name)) for f in cls.FIELDS} == vec["fields"]
    raw = msg.to_raw()
    assert {k: list(v) if isinstance(v, tuple) else v for k, v in raw.items()} == vec["raw"]
    assert msg.encode() == body
    assert encode_frame(vec["seq"], cls.ID, body).hex() == vec["frame"]


@pytest.mark.parametrize("vec", MESSAGES["messages"], ids=_id)
def test_cpp_codec_matches_message_vector(cpp: CppCodec, vec: dict[str, Any]) -> None:
    cls = M.BY_NAME[vec["name"]]
    body = bytes.fromhex(vec["body"])
    frame = bytes.fromhex(vec["frame"])
    assert cpp.message_size(cls.ID) == cls.SIZE
    assert cpp.decode_stream(frame) == [Frame(vec["seq"], cls.ID, body)]
    assert cpp.encode_frame(vec["seq"], cls.ID, body) == frame
    result = cpp.decode_message(cls.ID, body)
    assert (result.status, result.bad_field) == (0, 0xFF)
    expected = flat_raw(cls, vec["raw"])
    assert len(result.values) == len(expected)
    for got, want in zip(result.values, expected, strict=True):
        assert got == want or (math.isnan(got) and math.isnan(want))
    assert result.reencoded == body
    # The C++ encoder, from the vector's raw values alone, makes the same bytes.
    assert cpp.encode_message(cls.ID, expected) == body


@pytest.mark.parametrize("vec", MESSAGES["invalid"], ids=_id)
def test_both_codecs_refuse_invalid_body(cpp: CppCodec, vec: dict[str, Any]) -> None:
    cls = M.BY_NAME[vec["name"]]
    body = bytes.fromhex(vec["body"])
    with pytest.raises(DecodeError) as info:
        cls.decode(body)
    assert info.value.message == cls.NAME
    result = cpp.decode_message(cls.ID, body)
    if vec["error"] == "bad_length":
        assert info.value.field is None
        assert (result.status, result.bad_field) == (1, 0xFF)
    else:
        assert info.value.field is not None
        assert info.value.field.split("[")[0] == vec["field"]
        assert vec["field"] in str(info.value)
        assert (result.status, result.bad_field) == (2, vec["field_index"])


def test_request_metadata_matches_vectors() -> None:
    for name, meta in MESSAGES["requests"].items():
        cls = M.BY_NAME[name]
        assert meta["reply"] == cls.REPLY.NAME
        assert meta["idempotent"] == cls.IDEMPOTENT
        assert meta["reply_timeout_s"] == cls.REPLY_TIMEOUT_S


# --- streams ------------------------------------------------------------------------------


@pytest.mark.parametrize("vec", STREAMS["streams"], ids=lambda v: v["name"])
def test_python_decoder_delivers_stream_vector(vec: dict[str, Any]) -> None:
    data = bytes.fromhex(vec["bytes"])
    assert events_json(decode_stream(data)) == vec["expect"]


@pytest.mark.parametrize("vec", STREAMS["streams"], ids=lambda v: v["name"])
def test_cpp_decoder_delivers_stream_vector(cpp: CppCodec, vec: dict[str, Any]) -> None:
    data = bytes.fromhex(vec["bytes"])
    assert events_json(cpp.decode_stream(data)) == vec["expect"]
    assert events_json(cpp.decode_stream(data, chunks=[1, 7, 3] * len(data))) == vec["expect"]


# --- hand-derived examples ----------------------------------------------------------------


def bitwise_crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE written from its definition, independent of both codecs."""
    crc = 0xFFFF
    for byte in data:
        for bit in range(7, -1, -1):
            top = ((crc >> 15) & 1) ^ ((byte >> bit) & 1)
            crc = (crc << 1) & 0xFFFF
            if top:
                crc ^= 0x1021
    return crc


@pytest.mark.parametrize("vec", HANDMADE["crc16_ccitt_false"], ids=lambda v: v["data"][:12])
def test_crc_matches_hand_derivation(cpp: CppCodec, vec: dict[str, Any]) -> None:
    data, want = bytes.fromhex(vec["data"]), int(vec["crc"], 16)
    assert bitwise_crc16(data) == want
    assert crc16_ccitt(data) == want
    assert cpp.crc16(data) == want


@pytest.mark.parametrize("vec", HANDMADE["cobs"], ids=lambda v: v["raw"])
def test_cobs_matches_hand_derivation(cpp: CppCodec, vec: dict[str, Any]) -> None:
    raw, encoded = bytes.fromhex(vec["raw"]), bytes.fromhex(vec["encoded"])
    assert cobs.encode(raw) == encoded
    assert cobs.decode(encoded) == raw
    # The firmware's encoder COBS-encodes seq | id | body | crc: give it raw as those bytes.
    if len(raw) >= 2:
        crc = crc16_ccitt(raw).to_bytes(2, "little")
        assert cpp.encode_frame(raw[0], raw[1], raw[2:]) == cobs.encode(raw + crc) + b"\x00"


@pytest.mark.parametrize("vec", HANDMADE["frames"], ids=lambda v: v["what"][:20])
def test_frames_match_hand_derivation(cpp: CppCodec, vec: dict[str, Any]) -> None:
    body, frame = bytes.fromhex(vec["body"]), bytes.fromhex(vec["frame"])
    seq, msg_id = vec["seq"], vec["msg_id"]
    assert encode_frame(seq, msg_id, body) == frame
    assert cpp.encode_frame(seq, msg_id, body) == frame
    assert decode_stream(frame) == [Frame(seq, msg_id, body)]
    assert cpp.decode_stream(frame) == [Frame(seq, msg_id, body)]
    if "message" in vec:
        cls = M.BY_NAME[vec["message"]]
        assert msg_id == cls.ID
        assert cls.decode(body).to_raw() == vec["fields"]


@pytest.mark.parametrize("vec", HANDMADE["streams"], ids=lambda v: v["what"][:20])
def test_streams_match_hand_derivation(cpp: CppCodec, vec: dict[str, Any]) -> None:
    data = bytes.fromhex(vec["bytes"])
    assert events_json(decode_stream(data)) == vec["expect"]
    assert events_json(cpp.decode_stream(data)) == vec["expect"]
