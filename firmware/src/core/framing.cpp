#include "framing.h"

#include "../generated/protocol_messages.h"

namespace utrf {
namespace framing {

static_assert(kMaxBodyBytes == proto::kMaxPayload, "framing and the spec disagree on the payload");
static_assert(kMaxEncodedBytes < 254, "one COBS block must hold a whole frame");

uint16_t crc16_ccitt(const uint8_t* data, uint16_t len, uint16_t crc) {
  // A byte at a time with no table (no flash or SRAM for 256 entries). For the polynomial
  // x^16 + x^12 + x^5 + 1, the table entry of v = (crc >> 8) ^ byte is v * x^16 mod P; since
  // x^16 = x^12 + x^5 + 1 (mod P), folding v's high nibble back in gives, with
  // w = v ^ (v >> 4): entry = (w << 12) ^ (w << 5) ^ w (16 bits).
  // The two CRC bytes are kept apart: an 8-bit AVR has no 16-bit shift by 5, but (w << 5)
  // is (w >> 3) in the high byte and (w << 5) in the low one.
  uint8_t hi = static_cast<uint8_t>(crc >> 8);
  uint8_t lo = static_cast<uint8_t>(crc);
  for (uint16_t i = 0; i < len; ++i) {
    uint8_t w = static_cast<uint8_t>(hi ^ data[i]);
    w = static_cast<uint8_t>(w ^ (w >> 4));
    hi = static_cast<uint8_t>(lo ^ static_cast<uint8_t>(w << 4) ^ static_cast<uint8_t>(w >> 3));
    lo = static_cast<uint8_t>(static_cast<uint8_t>(w << 5) ^ w);
  }
  return static_cast<uint16_t>((static_cast<uint16_t>(hi) << 8) | lo);
}

uint8_t encode_frame(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len, uint8_t* out) {
  if (len > kMaxBodyBytes) return 0;
  FrameWriter w(out, seq, msg_id);
  for (uint8_t i = 0; i < len; ++i) w.put(body[i]);
  return w.finish();
}

FrameDecoder::FrameDecoder() : len_(0), body_len_(0), discarding_(false) {}

void FrameDecoder::reset() {
  len_ = 0;
  body_len_ = 0;
  discarding_ = false;
}

RxEvent FrameDecoder::feed_rest(uint8_t byte) {
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
