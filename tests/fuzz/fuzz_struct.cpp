// libFuzzer harness, structure-aware: the input is a script of operations on one board. Most
// are requests, each wrapped in a valid COBS + CRC frame with the next seq; the others are
// time (ticks and loop() passes), encoder ADC values, a stopped sampler, the EEPROM busy or a
// stuck cell, power cycles, a hung loop(), a stopped tick, a tick overrun, flipped frames and
// raw bytes. Beyond fuzz_board.h's oracles: every request gets exactly one reply, with its
// seq, of the kind the request calls for.
//
// Script bytes (tests/fuzz/make_seeds.py writes the seeds in it):
//   0x00-0x7F  request: msg_id, body length, body
//   0x80       run: n (1..256 ms)
//   0x81       ADC: finger, code (2 bytes, little-endian, modulo 1024)
//   0x82       EEPROM: busy polls per byte (0..3), stuck cell (u16 LE; 0xFFFF none)
//   0x83       power cycle: reset cause, erase EEPROM (bit 0)
//   0x84       loop() hangs for n ticks (then the watchdog resets a halted board)
//   0x85       the tick stops for n ms while loop() runs (then the watchdog resets)
//   0x86       one tick overruns
//   0x87       flipped frame: msg_id, body length, body, bit (u16 LE)
//   0x88       raw bytes: n, bytes (then a lone 0x00)
//   0x89       sampler: frozen (bit 0)
//   others     ignored
#include "fuzz_board.h"

namespace {

using namespace utrf;

fuzz::Board g;

struct Script {
    const uint8_t* p;
    size_t n;
    bool more() const { return n > 0; }
    uint8_t u8() {
        if (n == 0) return 0;
        --n;
        return *p++;
    }
    uint16_t u16() {
        const uint8_t lo = u8();
        return (uint16_t)(lo | (u8() << 8));
    }
};

// The reply a request calls for besides ack and nack (0: ack only).
int reply_id(uint8_t req) {
    switch (req) {
#define UTRF_FUZZ_REPLY(Msg, ID)                                             \
    case proto::Msg::kId:                                                    \
        return proto::Msg::kReplyId == proto::Ack::kId ? 0 : proto::Msg::kReplyId;
        UTRF_PROTO_REQUESTS(UTRF_FUZZ_REPLY)
#undef UTRF_FUZZ_REPLY
        default: return 0;
    }
}

uint8_t g_seq;

uint8_t next_seq() {
    g_seq = (uint8_t)((g_seq + 1) & 0x7F);
    return g_seq;
}

void request(Script& s) {
    const uint8_t id = s.u8();
    uint8_t len = s.u8();
    if (len > proto::kMaxPayload) len = proto::kMaxPayload;
    uint8_t body[proto::kMaxPayload];
    for (uint8_t i = 0; i < len; ++i) body[i] = s.u8();
    const uint8_t seq = next_seq();
    g.forget_replies();
    g.send_frame(seq, id, body, len, -1);
    // Until the reply, or 2 s (a full save_config with a busy EEPROM takes about 1.3 s here).
    fuzz::Reply r[fuzz::Board::kMaxReplies];
    int got = 0;
    for (int ms = 0; ms < 2000 && got == 0; ++ms) {
        if (g.budget_ms == 0) return;  // out of time for this input: no verdict
        g.run(1);
        got = g.take_replies(r, fuzz::Board::kMaxReplies);
    }
    g.run(2);
    got += g.take_replies(r + got, fuzz::Board::kMaxReplies - got);
    g.check_config();
    FUZZ_CHECK(got == 1, "request 0x%02X seq %u: %d replies", id, seq, got);
    FUZZ_CHECK(r[0].seq == seq, "request seq %u answered with seq %u", seq, r[0].seq);
    if (r[0].msg_id == proto::Ack::kId || r[0].msg_id == proto::Nack::kId) {
        FUZZ_CHECK(r[0].body[0] == id, "request 0x%02X acked or nacked as 0x%02X", id,
                   r[0].body[0]);
        if (r[0].msg_id == proto::Ack::kId) {
            FUZZ_CHECK(reply_id(id) == 0, "request 0x%02X acked, not answered", id);
        }
    } else {
        FUZZ_CHECK(r[0].msg_id == reply_id(id), "request 0x%02X answered with 0x%02X", id,
                   r[0].msg_id);
    }
}

void after_noise() {
    static const uint8_t kZero = 0;
    g.send(&kZero, 1);  // ends whatever partial frame the board holds
    g.run(5);
    g.forget_replies();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    Script s = {data, size};
    g_seq = 0;
    g.set_eeprom(0, -1);
    g.budget_ms = 0xFFFFFFFFu;
    g.power_on(0, true);
    g.run(2);
    // At most 4 s of board time an input (a full save with a busy EEPROM takes 1.3 s).
    g.budget_ms = 4000;
    int ops = 0;
    while (s.more() && ops++ < 200 && g.budget_ms > 0) {
        const uint8_t op = s.u8();
        if (op < 0x80) {
            // The op byte is the first body-length guess's neighbour: re-read as the msg_id.
            Script r = {s.p - 1, s.n + 1};
            request(r);
            s = r;
            continue;
        }
        switch (op) {
            case 0x80:
                g.run((uint32_t)s.u8() + 1);
                break;
            case 0x81: {
                const uint8_t f = (uint8_t)(s.u8() % 5);
                fw_set_adc(f, (uint16_t)(s.u16() % 1024));
                g.run(1);
                break;
            }
            case 0x82: {
                const uint8_t polls = (uint8_t)(s.u8() % 4);
                const uint16_t stuck = s.u16();
                g.set_eeprom(polls, stuck == 0xFFFF ? -1 : (int32_t)(stuck % config::kImageBytes));
                break;
            }
            case 0x83: {
                const uint8_t cause = (uint8_t)(s.u8() % 6);
                g.power_on(cause, (s.u8() & 1) != 0);
                g.run(2);
                break;
            }
            case 0x84: {
                const uint32_t n = s.u8();
                g.tick(n);
                if (app::board().hand.halted()) {
                    g.loop(1);  // loop() comes back, but no longer feeds the watchdog
                    g.power_on(3, false);
                    g.run(2);
                }
                break;
            }
            case 0x85: {
                const uint32_t n = s.u8();
                for (uint32_t i = 0; i < n; ++i) {
                    fw_advance_ms(1);
                    g.loop(1);
                }
                if (hal::host::state().hang_mark) {
                    g.power_on(3, false);
                    g.run(2);
                }
                break;
            }
            case 0x86:
                fw_set_period_elapsed(1);
                g.tick(1);
                fw_set_period_elapsed(0);
                g.run(2);
                break;
            case 0x87: {
                const uint8_t id = s.u8();
                uint8_t len = s.u8();
                if (len > proto::kMaxPayload) len = proto::kMaxPayload;
                uint8_t body[proto::kMaxPayload];
                for (uint8_t i = 0; i < len; ++i) body[i] = s.u8();
                g.send_frame(next_seq(), id, body, len, s.u16());
                after_noise();
                break;
            }
            case 0x88: {
                uint8_t raw[255];
                const uint8_t n = s.u8();
                for (uint8_t i = 0; i < n; ++i) raw[i] = s.u8();
                g.send(raw, n);
                after_noise();
                break;
            }
            case 0x89:
                fw_freeze_adc(s.u8() & 1);
                g.run(1);
                break;
            default:
                break;
        }
    }
    g.budget_ms = 20;
    g.run(20);
    return 0;
}
