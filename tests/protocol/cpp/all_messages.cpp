// Instantiates every generated decode/encode, so the AVR and host compile tests see all of
// them (inline functions that are never called are not fully checked by every compiler).
#include "../../../firmware/src/core/framing.h"
#include "../../../firmware/src/generated/protocol_messages.h"

using namespace utrf;

extern "C" uint8_t utrf_all_messages(const uint8_t* body, uint8_t len, uint8_t* out);

extern "C" uint8_t utrf_all_messages(const uint8_t* body, uint8_t len, uint8_t* out) {
  uint8_t bad = 0;
  uint8_t total = 0;
#define UTRF_TRY(Type, NAME)                                             \
  {                                                                      \
    proto::Type m;                                                       \
    if (proto::decode(body, len, m, bad) == proto::DecodeStatus::OK) {   \
      total = static_cast<uint8_t>(total + proto::encode(m, out));       \
    }                                                                    \
  }
  UTRF_PROTO_MESSAGES(UTRF_TRY)
#undef UTRF_TRY
  framing::FrameDecoder decoder;
  for (uint8_t i = 0; i < len; ++i) {
    if (decoder.feed(body[i]) == framing::RxEvent::FRAME) total ^= decoder.msg_id();
  }
  return static_cast<uint8_t>(total + bad + proto::next_board_seq(total) +
                              framing::encode_frame(1, 2, body, len, out));
}
