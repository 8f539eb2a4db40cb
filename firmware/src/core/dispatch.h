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
void fill_boot(const app::Board& b, proto::Boot& m);

}  // namespace dispatch
}  // namespace utrf

#endif  // UTRF_CORE_DISPATCH_H
