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

FrameDecoder::FrameDecoder() : body_len_(0), discarding_(false) { start(); }

void FrameDecoder::start() {
  len_ = 0;
  out_ = 0;
  st_.left = 0;
  st_.hi = 0xFF;
  st_.lo = 0xFF;
  st_.d1 = 0;
  st_.d2 = 0;
  st_.lag = kCrcBytes;
  st_.zero = false;
}

void FrameDecoder::reset() {
  start();
  body_len_ = 0;
  discarding_ = false;
}

RxEvent FrameDecoder::feed_rest(uint8_t byte) {
  if (byte == 0x00) {
    if (discarding_) {
      discarding_ = false;
      start();
      return RxEvent::NONE;
    }
    if (len_ == 0) return RxEvent::NONE;  // empty frame: a spare delimiter
    RxEvent ev = finish();
    start();
    return ev;
  }
  if (discarding_) return RxEvent::NONE;
  if (len_ == kMaxEncodedBytes) {
    discarding_ = true;
    return RxEvent::OVERSIZE;
  }
  ++len_;
  take(byte);
  return RxEvent::NONE;
}

// The frame's 0x00: its bytes are decoded and the CRC run over all but the last two. A block
// whose code claims more bytes than came before the 0x00 is a framing error. A frame holds
// fewer than 254 bytes, so a code 0xFF (254 bytes, no zero after them) can never be complete.
RxEvent FrameDecoder::finish() {
  if (st_.left != 0) return RxEvent::FRAMING_ERROR;
  const uint8_t n = out_;
  if (n < kMinRawBytes) return RxEvent::FRAMING_ERROR;
  const uint8_t payload = static_cast<uint8_t>(n - kCrcBytes);
  const uint16_t got = static_cast<uint16_t>(buf_[payload] | (buf_[payload + 1] << 8));
  body_len_ = static_cast<uint8_t>(payload - kHeaderBytes);
  if (static_cast<uint16_t>((static_cast<uint16_t>(st_.hi) << 8) | st_.lo) != got) {
    return RxEvent::CRC_ERROR;
  }
  return RxEvent::FRAME;
}

}  // namespace framing
}  // namespace utrf
