// Protocol dispatch: one valid frame in, at most one reply out (through app::queue_reply).
//
// Every request is decoded and checked completely before anything changes; a refused
// request is answered with a nack naming the field or finger, and changes nothing.
#ifndef UTRF_CORE_DISPATCH_H
#define UTRF_CORE_DISPATCH_H

#include <stdint.h>

#include "../generated/protocol_messages.h"
#include "app.h"

namespace utrf {
namespace dispatch {

void handle(app::Board& b, uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len);
void nack(app::Board& b, uint8_t seq, uint8_t msg_id, uint8_t code, uint8_t detail);
void ack(app::Board& b, uint8_t seq, uint8_t msg_id);

// Board-initiated messages (used by app for the stream and reports).
// The state frame with this seq for sample `s`, written into `out` (kMaxFrameBytes); its
// length. With `start`: into a 256-byte ring from that index (the UART's, in place); the index
// after the frame.
uint8_t write_state_frame(app::Board& b, uint8_t seq, const hand::StateSample& s, uint8_t* out,
                          uint8_t start = 0);
void fill_status(const app::Board& b, proto::Status& m);
// The JOINT2_ANGLE set_targets values (micro-radians) a finger with these joint limits (BU)
// accepts, [lo, hi]: exactly those whose count lies within a count of the limits (lo > hi:
// none). Worked out when the limits change, so that set_targets checks its values before it
// converts them, and acks before.
void target_window(int16_t theta_min, int16_t theta_max, int32_t& lo, int32_t& hi);
static const int32_t kMaxUrad = 4000000L;  // beyond +-pi: refused before the conversion
// Micro-radians (set_targets' JOINT2_ANGLE) to BU, to the nearest count, in integers:
// x 32768 / (2 pi 1e6) as x * M / 2^32. M is within 2e-9 of exact: below 1e-4 count off for
// any angle the board can hold.
// The 64-bit product is formed from 32-bit ones (avr-gcc's 64-bit arithmetic is slow:
// firmware/README.md, Timing): with M = 2^16 Mh + Ml and
// x = 2^16 xh + xl (xl the low 16 bits, unsigned; xh = x >> 16, floor),
// x M + 2^31 = 2^16 (x Mh + xh Ml + 2^15) + xl Ml, and since xl Ml < 2^32,
// floor((x M + 2^31) / 2^32) = (x Mh + xh Ml + (xl Ml >> 16) + 2^15) >> 16 exactly.
// |x| <= kMaxUrad keeps every term in 32 bits. (The host tests compare it with the 64-bit
// form over the whole range.)
inline int32_t bu_from_urad(int32_t urad) {
    static const uint16_t kMh = 341;    // round(2^32 * 32768 / (2 pi 1e6)) = 22399067
    static const uint16_t kMl = 51291;  //   = 341 * 65536 + 51291
    const int16_t xh = (int16_t)(urad >> 16);
    const uint16_t xl = (uint16_t)urad;
    const int32_t s = urad * (int32_t)kMh + (int32_t)xh * (int32_t)kMl +
                      (int32_t)(((uint32_t)xl * kMl) >> 16) + 0x8000L;
    return s >> 16;
}

void fill_boot(const app::Board& b, proto::Boot& m);

}  // namespace dispatch
}  // namespace utrf

#endif  // UTRF_CORE_DISPATCH_H
