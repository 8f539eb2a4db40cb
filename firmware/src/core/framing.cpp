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
  for (uint16_t i = 0; i < len; ++i) crc_step(hi, lo, data[i]);
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

// Decodes the COBS bytes in place (the output never overtakes the input) and checks the CRC,
// in one pass over the bytes with pointers (an index a byte cost the AVR twice the cycles).
// A frame holds fewer than 254 bytes, so every valid block is shorter than 255 and stands for
// a zero after it (except the last, whose zero is the delimiter): the decoded frame is one
// byte shorter than the encoded, and the CRC covers all of it but its last two bytes. (A code
// 0xFF would claim 254 bytes, more than any frame holds: it fails the length check.)
RxEvent FrameDecoder::finish() {
  const uint8_t* in = buf_;
  const uint8_t* const end = buf_ + len_;
  uint8_t* out = buf_;
  uint8_t crc_left = static_cast<uint8_t>(len_ - 1u - kCrcBytes);  // wraps when too short
  uint8_t hi = 0xFF;
  uint8_t lo = 0xFF;
  while (in != end) {
    const uint8_t code = *in++;
    // A code counts itself and the code-1 bytes after it; none of them may be past the end.
    if (code - 1 > end - in) return RxEvent::FRAMING_ERROR;
    for (uint8_t k = code; k > 1; --k) {
      const uint8_t byte = *in++;
      *out++ = byte;
      if (crc_left != 0) {
        --crc_left;
        crc_step(hi, lo, byte);
      }
    }
    if (in != end) {
      *out++ = 0x00;
      if (crc_left != 0) {
        --crc_left;
        crc_step(hi, lo, 0x00);
      }
    }
  }
  const uint8_t n = static_cast<uint8_t>(out - buf_);
  if (n < kMinRawBytes) return RxEvent::FRAMING_ERROR;
  const uint8_t payload = static_cast<uint8_t>(n - kCrcBytes);
  const uint16_t got = static_cast<uint16_t>(buf_[payload] | (buf_[payload + 1] << 8));
  body_len_ = static_cast<uint8_t>(payload - kHeaderBytes);
  if (static_cast<uint16_t>((static_cast<uint16_t>(hi) << 8) | lo) != got) {
    return RxEvent::CRC_ERROR;
  }
  return RxEvent::FRAME;
}

}  // namespace framing
}  // namespace utrf
