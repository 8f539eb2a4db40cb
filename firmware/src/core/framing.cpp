#include "framing.h"

#include "../generated/protocol_messages.h"

namespace utrf {
namespace framing {

static_assert(kMaxBodyBytes == proto::kMaxPayload, "framing and the spec disagree on the payload");
static_assert(kMaxEncodedBytes < 254, "one COBS block must hold a whole frame");

uint16_t crc16_ccitt(const uint8_t* data, uint16_t len, uint16_t crc) {
  // Byte-wise form of the bitwise MSB-first division by 0x1021 (same results): the top
  // byte's contribution folded in with shifts, no table. About 30 cycles a byte on the AVR
  // against ~100 for eight single-bit steps; a 70-byte state frame at 500 Hz makes it count.
  for (uint16_t i = 0; i < len; ++i) {
    uint8_t x = static_cast<uint8_t>((crc >> 8) ^ data[i]);
    x ^= static_cast<uint8_t>(x >> 4);
    // x * 32 rather than x << 5: avr-gcc makes the shift a 5-step loop, the product swaps.
    crc = static_cast<uint16_t>((crc << 8) ^ (static_cast<uint16_t>(x) << 12) ^
                                (static_cast<uint16_t>(x) * 32u) ^ x);
  }
  return crc;
}

uint8_t encode_frame(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len, uint8_t* out) {
  if (len > kMaxBodyBytes) return 0;
  const uint8_t header[kHeaderBytes] = {seq, msg_id};
  uint16_t crc = crc16_ccitt(header, kHeaderBytes);
  crc = crc16_ccitt(body, len, crc);
  const uint8_t raw_len = static_cast<uint8_t>(len + kHeaderBytes + kCrcBytes);
  // COBS, streamed over header | body | crc without assembling them first. A frame is at most
  // 68 bytes, below the 254-byte block limit, so a block ends only at a zero or at the end.
  uint8_t code_at = 0;  // where the current block's code byte goes
  uint8_t n = 1;
  for (uint8_t i = 0; i < raw_len; ++i) {
    uint8_t b;
    if (i < kHeaderBytes) {
      b = header[i];
    } else if (i < kHeaderBytes + len) {
      b = body[i - kHeaderBytes];
    } else if (i == kHeaderBytes + len) {
      b = static_cast<uint8_t>(crc);
    } else {
      b = static_cast<uint8_t>(crc >> 8);
    }
    if (b == 0) {
      out[code_at] = static_cast<uint8_t>(n - code_at);
      code_at = n++;
    } else {
      out[n++] = b;
    }
  }
  out[code_at] = static_cast<uint8_t>(n - code_at);
  out[n++] = 0x00;
  return n;
}

FrameDecoder::FrameDecoder() : len_(0), body_len_(0), discarding_(false) {}

void FrameDecoder::reset() {
  len_ = 0;
  body_len_ = 0;
  discarding_ = false;
}

RxEvent FrameDecoder::feed(uint8_t byte) {
  if (byte == 0x00) {
    if (discarding_) {
      discarding_ = false;
      len_ = 0;
      return RxEvent::NONE;
    }
    if (len_ == 0) return RxEvent::NONE;  // empty frame: a spare delimiter
    RxEvent ev = finish();
    len_ = 0;
    return ev;
  }
  if (discarding_) return RxEvent::NONE;
  if (len_ == kMaxEncodedBytes) {
    discarding_ = true;
    return RxEvent::OVERSIZE;
  }
  buf_[len_++] = byte;
  return RxEvent::NONE;
}

// Decodes the COBS bytes in place (the output never overtakes the input) and checks the CRC.
RxEvent FrameDecoder::finish() {
  uint8_t in = 0;
  uint8_t out = 0;
  while (in < len_) {
    const uint8_t code = buf_[in++];
    // A code counts itself and the code-1 bytes after it; none of them may be past the end.
    if (static_cast<uint16_t>(in) + code - 1u > len_) return RxEvent::FRAMING_ERROR;
    for (uint8_t k = 1; k < code; ++k) buf_[out++] = buf_[in++];
    // A block shorter than 255 stands for a zero, except the last, whose zero is the delimiter.
    if (code < 0xFF && in < len_) buf_[out++] = 0x00;
  }
  if (out < kMinRawBytes) return RxEvent::FRAMING_ERROR;
  const uint8_t payload = static_cast<uint8_t>(out - kCrcBytes);
  const uint16_t got = static_cast<uint16_t>(buf_[payload] | (buf_[payload + 1] << 8));
  body_len_ = static_cast<uint8_t>(payload - kHeaderBytes);
  if (crc16_ccitt(buf_, payload) != got) return RxEvent::CRC_ERROR;
  return RxEvent::FRAME;
}

}  // namespace framing
}  // namespace utrf
