"""Frames on the wire: ``COBS(seq | msg_id | body | crc16) 0x00``.

The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected), little-endian, over
seq, msg_id and the body. COBS removes every 0x00, so 0x00 only ever ends a frame: a receiver
resynchronises at the next one whatever came before, and never trusts a length. The same
rules as the firmware's ``core/framing.cpp``, event for event (tested on the same streams).
"""

from __future__ import annotations

import binascii
from dataclasses import dataclass
from enum import IntEnum

from cobs import cobs

from utrf.protocol.messages import MAX_PAYLOAD

HEADER_BYTES = 2  # seq, msg_id
CRC_BYTES = 2
MAX_BODY_BYTES = MAX_PAYLOAD
MAX_RAW_BYTES = HEADER_BYTES + MAX_BODY_BYTES + CRC_BYTES  # 68
MIN_RAW_BYTES = HEADER_BYTES + CRC_BYTES
MAX_ENCODED_BYTES = MAX_RAW_BYTES + (MAX_RAW_BYTES + 253) // 254  # 69: one COBS code byte
MAX_FRAME_BYTES = MAX_ENCODED_BYTES + 1  # 70, with the closing 0x00
DELIMITER = b"\x00"


def crc16_ccitt(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of ``data``; pass a previous result as ``crc`` to continue."""
    return binascii.crc_hqx(data, crc)


def encode_frame(seq: int, msg_id: int, body: bytes = b"") -> bytes:
    """The complete frame, closing 0x00 included."""
    if not 0 <= seq <= 0xFF:
        raise ValueError(f"seq {seq} is not a byte (0..255)")
    if not 0 <= msg_id <= 0xFF:
        raise ValueError(f"msg_id {msg_id} is not a byte (0..255)")
    if len(body) > MAX_BODY_BYTES:
        raise ValueError(f"body of {len(body)} bytes is above the {MAX_BODY_BYTES}-byte maximum")
    raw = bytes((seq, msg_id)) + bytes(body)
    raw += crc16_ccitt(raw).to_bytes(2, "little")
    return cobs.encode(raw) + DELIMITER


class RxEvent(IntEnum):
    """What the receiver reports (the same numbers as ``utrf::framing::RxEvent``)."""

    NONE = 0
    FRAME = 1
    CRC_ERROR = 2  # a well-formed frame whose CRC failed; seq/msg_id as received (a hint)
    FRAMING_ERROR = 3  # bad COBS, or fewer than 4 bytes after decoding
    OVERSIZE = 4  # more than MAX_ENCODED_BYTES before a 0x00: dropped up to the next 0x00


@dataclass(frozen=True, slots=True)
class Frame:
    """A frame that passed its CRC. ``body`` is not yet checked against any message."""

    seq: int
    msg_id: int
    body: bytes


@dataclass(frozen=True, slots=True)
class FrameError:
    """A damaged frame. For CRC_ERROR, ``seq`` and ``msg_id`` are the bytes as received."""

    kind: RxEvent
    seq: int | None = None
    msg_id: int | None = None


class FrameDecoder:
    """Streaming receiver: feed it bytes as they come, get frames and errors in order.

    Empty frames (0x00 right after 0x00) are ignored, so a sender may send a lone 0x00 to
    end whatever partial frame the receiver holds. OVERSIZE is reported once, as soon as the
    pending frame outgrows MAX_ENCODED_BYTES; the rest, up to the next 0x00, is dropped.
    """

    def __init__(self) -> None:
        self._pending = bytearray()
        self._discarding = False

    def reset(self) -> None:
        """Forget any partial frame."""
        self._pending.clear()
        self._discarding = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame | FrameError]:
        events: list[Frame | FrameError] = []
        *complete, rest = bytes(data).split(DELIMITER)
        for part in complete:
            if self._discarding:
                self._discarding = False
                continue
            encoded = bytes(self._pending) + part
            self._pending.clear()
            if len(encoded) > MAX_ENCODED_BYTES:
                events.append(FrameError(RxEvent.OVERSIZE))
            elif encoded:
                events.append(_finish(encoded))
        if not self._discarding:
            self._pending += rest
            if len(self._pending) > MAX_ENCODED_BYTES:
                events.append(FrameError(RxEvent.OVERSIZE))
                self._pending.clear()
                self._discarding = True
        return events


def _finish(encoded: bytes) -> Frame | FrameError:
    try:
        raw = cobs.decode(encoded)
    except cobs.DecodeError:
        return FrameError(RxEvent.FRAMING_ERROR)
    if len(raw) < MIN_RAW_BYTES:
        return FrameError(RxEvent.FRAMING_ERROR)
    if crc16_ccitt(raw[:-CRC_BYTES]) != int.from_bytes(raw[-CRC_BYTES:], "little"):
        return FrameError(RxEvent.CRC_ERROR, raw[0], raw[1])
    return Frame(raw[0], raw[1], bytes(raw[HEADER_BYTES:-CRC_BYTES]))


def decode_stream(data: bytes) -> list[Frame | FrameError]:
    """Every event a fresh receiver reports for ``data`` (a convenience for tests and tools)."""
    return FrameDecoder().feed(data)
