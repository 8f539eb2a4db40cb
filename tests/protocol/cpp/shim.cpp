// C ABI over the firmware's framing and the generated message codec, for the pytest suite
// (loaded with ctypes from build/host/libutrf_proto.so). Host only.
#define UTRF_PROTO_FLATTEN
#include "../../../firmware/src/core/framing.h"
#include "../../../firmware/src/generated/protocol_messages.h"

using namespace utrf;

extern "C" {

// One record per reported event of utrf_decode_stream.
struct UtrfRxRecord {
  uint8_t event;  // framing::RxEvent
  uint8_t seq;
  uint8_t msg_id;
  uint8_t body_len;
  uint8_t body[framing::kMaxBodyBytes];
};

uint16_t utrf_crc16(const uint8_t* data, uint16_t len) { return framing::crc16_ccitt(data, len); }

uint8_t utrf_max_frame_bytes() { return framing::kMaxFrameBytes; }

uint8_t utrf_encode_frame(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len,
                          uint8_t* out) {
  return framing::encode_frame(seq, msg_id, body, len, out);
}

// One event's record: the frame's (or the damaged frame's) header, and a frame's body.
static void take_record(const framing::FrameDecoder& d, framing::RxEvent ev, UtrfRxRecord& r) {
  r.event = static_cast<uint8_t>(ev);
  r.seq = r.msg_id = r.body_len = 0;
  if (ev == framing::RxEvent::FRAME || ev == framing::RxEvent::CRC_ERROR) {
    r.seq = d.seq();
    r.msg_id = d.msg_id();
  }
  if (ev == framing::RxEvent::FRAME) {
    r.body_len = d.body_len();
    for (uint8_t k = 0; k < r.body_len; ++k) r.body[k] = d.body()[k];
  }
}

// Feeds `data` to `decoder` byte by byte and records every event other than NONE. Returns the
// number of events, or -1 if there were more than max_records.
int32_t utrf_decoder_feed(void* decoder, const uint8_t* data, uint32_t len, UtrfRxRecord* records,
                          uint32_t max_records) {
  framing::FrameDecoder& d = *static_cast<framing::FrameDecoder*>(decoder);
  uint32_t n = 0;
  for (uint32_t i = 0; i < len; ++i) {
    const framing::RxEvent ev = d.feed(data[i]);
    if (ev == framing::RxEvent::NONE) continue;
    if (n == max_records) return -1;
    take_record(d, ev, records[n++]);
  }
  return static_cast<int32_t>(n);
}

// The same through feed_run(), as the firmware's receive loop takes the bytes waiting in its
// ring: a run of a frame's bytes at once, and feed() for the byte that ends it (a 0x00, or the
// one that does not fit).
int32_t utrf_decoder_feed_runs(void* decoder, const uint8_t* data, uint32_t len,
                               UtrfRxRecord* records, uint32_t max_records) {
  framing::FrameDecoder& d = *static_cast<framing::FrameDecoder*>(decoder);
  uint32_t n = 0;
  uint32_t i = 0;
  while (i < len) {
    const uint32_t left = len - i;
    i += d.feed_run(data + i, static_cast<uint8_t>(left > 255 ? 255 : left));
    if (i == len) break;
    const framing::RxEvent ev = d.feed(data[i++]);
    if (ev == framing::RxEvent::NONE) continue;
    if (n == max_records) return -1;
    take_record(d, ev, records[n++]);
  }
  return static_cast<int32_t>(n);
}

void* utrf_decoder_new() { return new framing::FrameDecoder(); }
void utrf_decoder_free(void* decoder) { delete static_cast<framing::FrameDecoder*>(decoder); }
void utrf_decoder_reset(void* decoder) { static_cast<framing::FrameDecoder*>(decoder)->reset(); }

int16_t utrf_message_size(uint8_t msg_id) { return proto::message_size(msg_id); }

// Decodes `body` as message `msg_id`. Returns the DecodeStatus (0 OK, 1 BAD_LENGTH,
// 2 OUT_OF_RANGE) or -1 for an unknown id. On OK, `values` gets every scalar in wire order
// (*n_values of them) and `reencoded` the body encode() makes of the decoded struct.
int32_t utrf_decode_message(uint8_t msg_id, const uint8_t* body, uint8_t len, uint8_t* bad_field,
                            double* values, uint8_t* n_values, uint8_t* reencoded) {
  switch (msg_id) {
#define UTRF_CASE(Type, NAME)                                                   \
  case proto::MsgId::NAME: {                                                    \
    proto::Type m;                                                              \
    const proto::DecodeStatus st = proto::decode(body, len, m, *bad_field);     \
    if (st == proto::DecodeStatus::OK) {                                        \
      *n_values = proto::flatten(m, values);                                    \
      proto::encode(m, reencoded);                                              \
    }                                                                           \
    return static_cast<int32_t>(st);                                            \
  }
    UTRF_PROTO_MESSAGES(UTRF_CASE)
#undef UTRF_CASE
    default:
      return -1;
  }
}

// Encodes message `msg_id` from its scalars in wire order. Returns the body size, or -1.
int32_t utrf_encode_message(uint8_t msg_id, const double* values, uint8_t* body) {
  switch (msg_id) {
#define UTRF_CASE(Type, NAME)             \
  case proto::MsgId::NAME: {              \
    proto::Type m;                        \
    proto::unflatten(values, m);          \
    return proto::encode(m, body);        \
  }
    UTRF_PROTO_MESSAGES(UTRF_CASE)
#undef UTRF_CASE
    default:
      return -1;
  }
}

uint32_t utrf_schema_hash() { return proto::kSchemaHash; }
uint16_t utrf_protocol_version() { return proto::kProtocolVersion; }

}  // extern "C"
