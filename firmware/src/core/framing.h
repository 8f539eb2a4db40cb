// Framing of the host-board protocol: COBS, CRC-16/CCITT-FALSE and the sequence number.
//
// A frame on the wire is COBS(seq | msg_id | body | crc16) followed by one 0x00 byte. The CRC
// (poly 0x1021, init 0xFFFF, not reflected, little-endian on the wire) covers seq, msg_id and
// the body. COBS removes every 0x00 from the frame, so 0x00 only ever ends a frame and a
// receiver resynchronises at the next one, whatever came before: no length is trusted.
// Plain C++11 (no Arduino or AVR headers, no heap) so that it is tested on the host.
// protocol/README.md is the wire format for people.
#ifndef UTRF_CORE_FRAMING_H
#define UTRF_CORE_FRAMING_H

#include <stdint.h>

namespace utrf {
namespace framing {

static const uint8_t kHeaderBytes = 2;  // seq, msg_id
static const uint8_t kCrcBytes = 2;
static const uint8_t kMaxBodyBytes = 64;  // proto::kMaxPayload
static const uint8_t kMaxRawBytes = kHeaderBytes + kMaxBodyBytes + kCrcBytes;  // 68
static const uint8_t kMinRawBytes = kHeaderBytes + kCrcBytes;
// COBS adds one code byte per started run of 254 bytes, and a frame ends with 0x00.
static const uint8_t kMaxEncodedBytes = kMaxRawBytes + (kMaxRawBytes + 253) / 254;  // 69
static const uint8_t kMaxFrameBytes = kMaxEncodedBytes + 1;                          // 70

// One byte of crc16_ccitt() (framing.cpp explains it), the CRC kept as its two bytes.
inline void crc_step(uint8_t& hi, uint8_t& lo, uint8_t byte) {
  uint8_t w = static_cast<uint8_t>(hi ^ byte);
  w = static_cast<uint8_t>(w ^ (w >> 4));
  hi = static_cast<uint8_t>(lo ^ static_cast<uint8_t>(w << 4) ^ static_cast<uint8_t>(w >> 3));
  lo = static_cast<uint8_t>(static_cast<uint8_t>(w << 5) ^ w);
}
// CRC-16/CCITT-FALSE; pass a previous result as `crc` to continue over more bytes.
uint16_t crc16_ccitt(const uint8_t* data, uint16_t len, uint16_t crc = 0xFFFF);

// Writes the complete frame (COBS bytes and the closing 0x00) to `out`, which must hold
// kMaxFrameBytes, and returns its length; returns 0 (writing nothing) when len > kMaxBodyBytes.
uint8_t encode_frame(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len, uint8_t* out);

// Builds a frame as its bytes come: the CRC and the COBS codes are computed per byte, so a
// message is written straight into the frame (no body buffer, no second pass). put() the
// body's bytes (proto::write does, field by field), then finish() for the frame's length.
// `out` must hold kMaxFrameBytes; the body must fit kMaxBodyBytes (the spec's sizes do).
class FrameWriter {
 public:
  FrameWriter(uint8_t* out, uint8_t seq, uint8_t msg_id)
      : out_(out), pos_(1), code_at_(0), hi_(0xFF), lo_(0xFF) {
    put(seq);
    put(msg_id);
  }
  // Into a 256-byte ring from index `start`: the indices wrap by themselves (uint8_t), and
  // finish() returns the index after the frame.
  FrameWriter(uint8_t* ring, uint8_t start, uint8_t seq, uint8_t msg_id)
      : out_(ring), pos_(static_cast<uint8_t>(start + 1)), code_at_(start), hi_(0xFF), lo_(0xFF) {
    put(seq);
    put(msg_id);
  }
  void put(uint8_t byte) {
    crc_step(hi_, lo_, byte);  // the table-free CRC step of crc16_ccitt()
    stuff(byte);
  }
  // Appends the CRC (low byte first), the last code and the 0x00; returns the frame's length
  // (from a start index in a ring: the index after the frame).
  uint8_t finish() {
    const uint8_t hi = hi_;
    stuff(lo_);
    stuff(hi);
    out_[code_at_] = static_cast<uint8_t>(pos_ - code_at_);
    out_[pos_] = 0x00;
    return static_cast<uint8_t>(pos_ + 1);  // wraps with the ring's index
  }

 private:
  // COBS, one block (a frame is shorter than 254 bytes): a 0x00 becomes the code slot of
  // the block after it, and the slot before it gets that block's length.
  void stuff(uint8_t byte) {
    if (byte == 0) {
      out_[code_at_] = static_cast<uint8_t>(pos_ - code_at_);
      code_at_ = pos_;
    } else {
      out_[pos_] = byte;
    }
    ++pos_;
  }
  uint8_t* out_;
  uint8_t pos_;
  uint8_t code_at_;
  uint8_t hi_;
  uint8_t lo_;
};

enum class RxEvent : uint8_t {
  NONE = 0,       // byte taken; nothing to report yet
  FRAME,          // a valid frame: seq(), msg_id(), body(), body_len()
  CRC_ERROR,      // a well-formed frame whose CRC failed; seq()/msg_id() as received (a hint)
  FRAMING_ERROR,  // bad COBS, or fewer than kMinRawBytes after decoding
  OVERSIZE,       // more than kMaxEncodedBytes before a 0x00: the rest is dropped up to the 0x00
};

// Streaming receiver with a fixed buffer: feed it every byte from the line.
// Empty frames (0x00 right after 0x00) are ignored, so a sender may send a lone 0x00 to end
// whatever partial frame the receiver holds. OVERSIZE is reported once, at the first byte that
// does not fit; the bytes up to and including the next 0x00 are then dropped silently.
// Each byte is decoded as it is taken: its COBS undone (a block's zero is written when the
// next block's code comes, so the last block's, which is the delimiter's, never is) and the
// CRC run over the decoded bytes two behind (the last two are the CRC itself). What is left
// for the 0x00 is a few checks, so a request whose bytes were taken while they came is ready
// for dispatch at once.
class FrameDecoder {
 public:
  FrameDecoder();
  RxEvent feed(uint8_t byte) {
    // The common case inline: one more byte of a frame that still fits.
    if (byte != 0 && len_ < kMaxEncodedBytes && !discarding_) {
      ++len_;
      take(byte);
      return RxEvent::NONE;
    }
    return feed_rest(byte);
  }
  // Fast path: several bytes of a frame at once, as feed() would take them: data[0..n) up to
  // the first 0x00 (not taken: feed() it), and no further than the buffer holds (the byte
  // that does not fit goes to feed() too, which reports OVERSIZE). Returns how many it took.
  // The same rule as take() (decode()), its state in a local for the run: a store to buf_
  // may alias the members, so the compiler would reload them after each.
  uint8_t feed_run(const uint8_t* data, uint8_t n) {
    if (discarding_) return 0;
    const uint8_t room = static_cast<uint8_t>(kMaxEncodedBytes - len_);
    if (n > room) n = room;
    const uint8_t* p = data;
    const uint8_t* const end = data + n;
    uint8_t* out = buf_ + out_;
    Cobs s = st_;
    while (p != end) {
      uint8_t byte = *p;
      if (byte == 0) break;
      ++p;
      if (decode(s, byte)) *out++ = byte;
    }
    st_ = s;
    const uint8_t k = static_cast<uint8_t>(p - data);
    len_ = static_cast<uint8_t>(len_ + k);
    out_ = static_cast<uint8_t>(out - buf_);
    return k;
  }
  // Forget any partial frame (e.g. after the UART reported an overrun).
  void reset();
  // Bytes of a frame are in, its 0x00 not yet.
  bool in_frame() const { return len_ != 0 && !discarding_; }

  // After FRAME; after CRC_ERROR seq() and msg_id() are the damaged frame's bytes.
  // body() stays valid until the next call to feed().
  uint8_t seq() const { return buf_[0]; }
  uint8_t msg_id() const { return buf_[1]; }
  const uint8_t* body() const { return buf_ + kHeaderBytes; }
  uint8_t body_len() const { return body_len_; }
  // After FRAME: the frame's CRC as received (with seq and msg_id, it names one request).
  uint16_t crc() const {
    return static_cast<uint16_t>(buf_[kHeaderBytes + body_len_] |
                                 (buf_[kHeaderBytes + body_len_ + 1] << 8));
  }

 private:
  // Where the frame's decoding is between two bytes.
  struct Cobs {
    uint8_t left;  // bytes of the current COBS block still to come (0: the next is a code)
    uint8_t hi;    // the CRC so far, over the decoded bytes but the last two
    uint8_t lo;
    uint8_t d1;    // the last decoded byte and the one before it (not yet in the CRC)
    uint8_t d2;
    uint8_t lag;   // decoded bytes still to come before the CRC takes one (2 at the start)
    bool zero;     // a block was begun: the next code writes its zero
  };
  // One COBS byte of a frame, the rule both feeds run: a code starts a block (and yields the
  // zero the block before it stands for), any other is a decoded byte; the CRC runs two
  // decoded bytes behind. True with the decoded byte in `byte`.
  __attribute__((always_inline)) static bool decode(Cobs& s, uint8_t& byte) {
    if (s.left == 0) {
      s.left = static_cast<uint8_t>(byte - 1u);
      if (!s.zero) {
        s.zero = true;
        return false;
      }
      byte = 0x00;
    } else {
      --s.left;
    }
    if (s.lag != 0) {
      --s.lag;
    } else {
      crc_step(s.hi, s.lo, s.d2);
    }
    s.d2 = s.d1;
    s.d1 = byte;
    return true;
  }
  // The general path: one COBS byte of a frame (len_ already counts it).
  void take(uint8_t byte) {
    if (decode(st_, byte)) buf_[out_++] = byte;
  }
  void start();  // a new frame: nothing taken
  RxEvent feed_rest(uint8_t byte);
  RxEvent finish();

  uint8_t buf_[kMaxEncodedBytes];  // the decoded bytes (never more than the encoded)
  uint8_t len_;   // encoded bytes taken
  uint8_t out_;   // decoded bytes
  Cobs st_;
  uint8_t body_len_;
  bool discarding_;
};

}  // namespace framing
}  // namespace utrf

#endif  // UTRF_CORE_FRAMING_H
