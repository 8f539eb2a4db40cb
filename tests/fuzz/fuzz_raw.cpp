// libFuzzer harness: raw bytes into the board's UART receive path (the frame decoder, dispatch
// and the application), with control ticks and loop() passes interleaved, under ASan and
// UBSan, with the oracles of fuzz_board.h after every tick and every pass.
//
// Before the input arrives the board streams telemetry at the highest rate and every finger
// runs in closed loop, so what the input does is checked against a driving hand.
#include "fuzz_board.h"

namespace {

fuzz::Board g;

void preamble() {
    using namespace utrf;
    uint8_t body[proto::kMaxPayload];
    proto::SetTelemetry t;
    t.rate_hz = proto::kMaxTelemetryHz;
    g.send_frame(1, t.kId, body, proto::encode(t, body), -1);
    proto::SetMode m;
    memset(&m, 0, sizeof m);
    m.mask = 0x1F;
    for (uint8_t f = 0; f < 5; ++f) m.mode[f] = (uint8_t)proto::ControlMode::POSITION;
    g.send_frame(2, m.kId, body, proto::encode(m, body), -1);
    g.run(4);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    g.set_eeprom(0, -1);
    g.power_on(0, true);
    g.run(2);
    preamble();
    // The input in slices of up to 16 bytes, one millisecond apart (16 bytes is 160 us at
    // 1 Mbaud: the line is never faster than this).
    for (size_t i = 0; i < size; i += 16) {
        const size_t n = size - i < 16 ? size - i : 16;
        g.send(data + i, (uint16_t)n);
        g.run(1);
    }
    g.run(20);
    g.check_config();
    g.forget_replies();
    return 0;
}
