// The firmware core on the host under a fuzzer: one board (firmware/test's host HAL and its C
// ABI), the host's side of the line, and the oracles every harness asserts after each step.
//
// An oracle that fails prints what it saw and aborts, so libFuzzer records the input as a
// crash (tests/fuzz/crashes/ keeps each one found, replayed by the suite for ever after).
#ifndef UTRF_FUZZ_BOARD_H
#define UTRF_FUZZ_BOARD_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/app.h"
#include "core/config.h"
#include "core/finger.h"
#include "core/framing.h"
#include "generated/protocol_messages.h"
#include "hal_host.h"

extern "C" {
void fw_power_on(uint8_t reset_cause);
void fw_tick(uint32_t n);
void fw_loop(uint32_t n);
void fw_advance_ms(uint32_t ms);
void fw_set_adc(uint8_t f, uint16_t sample);
void fw_freeze_adc(int frozen);
void fw_set_period_elapsed(int on);
uint16_t fw_rx(const uint8_t* data, uint16_t n);
uint16_t fw_tx(uint8_t* out, uint16_t max);
void fw_set_eeprom_busy_polls(uint8_t n);
void fw_set_eeprom_stuck(int32_t addr);
}

namespace fuzz {

using namespace utrf;

#define FUZZ_CHECK(cond, ...)                                              \
    do {                                                                   \
        if (!(cond)) {                                                     \
            fprintf(stderr, "ORACLE %s:%d: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                  \
            fprintf(stderr, "\n");                                         \
            abort();                                                       \
        }                                                                  \
    } while (0)

// Every message the board may send, with its body size (the board never sends a request).
inline int board_msg_size(uint8_t id) {
    switch (id) {
#define UTRF_FUZZ_SIZE(Msg, ID) \
    case proto::Msg::kId:       \
        return proto::Msg::kSize;
        UTRF_PROTO_BOARD_MESSAGES(UTRF_FUZZ_SIZE)
#undef UTRF_FUZZ_SIZE
        default: return -1;
    }
}

// What the host side of the line saw since the last take_replies().
struct Reply {
    uint8_t seq;
    uint8_t msg_id;
    uint8_t body[framing::kMaxBodyBytes];
    uint8_t len;
};

class Board {
   public:
    static const int kMaxReplies = 64;

    // A fresh board: blank EEPROM (or kept), encoders mid-band.
    void power_on(uint8_t cause, bool erase_eeprom) {
        drain();  // what the board sent before the power went is checked too
        if (erase_eeprom) memset(hal::host::state().eeprom, 0xFF, hal::host::kEepromBytes);
        fw_power_on(cause);
        check_config();
        host_ = framing::FrameDecoder();
        last_seen_halted_ = false;
    }

    void set_eeprom(uint8_t busy_polls, int32_t stuck_addr) {
        fw_set_eeprom_busy_polls(busy_polls);
        fw_set_eeprom_stuck(stuck_addr);
    }

    // Simulated milliseconds left for this input (a bound on one execution's time).
    uint32_t budget_ms = 0xFFFFFFFFu;

    // One millisecond of normal running: the tick, then a loop() pass; oracles after each.
    void run(uint32_t ms) {
        for (uint32_t i = 0; i < ms && budget_ms > 0; ++i) {
            --budget_ms;
            tick(1);
            loop(1);
        }
    }

    void tick(uint32_t n) {
        for (uint32_t i = 0; i < n; ++i) {
            fw_tick(1);
            check_motors(true);
        }
    }

    void loop(uint32_t n) {
        for (uint32_t i = 0; i < n; ++i) {
            const bool saving = app::board().writer.busy();
            app::loop();
            check_motors(false);
            if (saving && !app::board().writer.busy() && !app::board().writer.failed()) {
                check_saved_image();
            }
            drain();
        }
    }

    void send(const uint8_t* data, uint16_t n) {
        const uint16_t taken = fw_rx(data, n);
        (void)taken;  // a full receive buffer drops the rest, as the UART would
    }

    // A complete frame for `seq`, `msg_id` and `body`; `flip_bit` >= 0 flips one bit of it.
    void send_frame(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len, int flip_bit) {
        uint8_t frame[framing::kMaxFrameBytes];
        const uint8_t n = framing::encode_frame(seq, msg_id, body, len, frame);
        FUZZ_CHECK(n != 0, "len %u", len);
        if (flip_bit >= 0) frame[(flip_bit / 8) % n] ^= (uint8_t)(1u << (flip_bit % 8));
        send(frame, n);
    }

    // Replies (seq without bit 7) seen since the last call.
    int take_replies(Reply* out, int max) {
        const int n = nreplies_ < max ? nreplies_ : max;
        memcpy(out, replies_, sizeof(Reply) * (size_t)n);
        nreplies_ = 0;
        return n;
    }
    void forget_replies() { nreplies_ = 0; }

   private:
    // The host's decoder over everything the board sends: only whole, valid frames of board
    // messages with their exact sizes.
    void drain() {
        uint8_t buf[512];
        for (;;) {
            const uint16_t n = fw_tx(buf, sizeof buf);
            if (n == 0) break;
            for (uint16_t i = 0; i < n; ++i) {
                const framing::RxEvent ev = host_.feed(buf[i]);
                FUZZ_CHECK(ev == framing::RxEvent::NONE || ev == framing::RxEvent::FRAME,
                           "the board sent a malformed frame (event %d)", (int)ev);
                if (ev != framing::RxEvent::FRAME) continue;
                const int size = board_msg_size(host_.msg_id());
                FUZZ_CHECK(size >= 0, "the board sent message id 0x%02X", host_.msg_id());
                FUZZ_CHECK(size == host_.body_len(), "message 0x%02X with %u bytes, not %d",
                           host_.msg_id(), host_.body_len(), size);
                // A board seq (bit 7) only on the board's own frames: never on a reply, so a
                // reply and a board frame cannot be confused (a BAD_CRC nack included).
                const uint8_t id = host_.msg_id();
                FUZZ_CHECK(!(host_.seq() & proto::kBoardSeqFlag) || id == proto::Boot::kId ||
                               id == proto::State::kId || id == proto::Status::kId ||
                               id == proto::Fault::kId,
                           "message 0x%02X with the board's seq %u", id, host_.seq());
                if (host_.seq() & proto::kBoardSeqFlag) continue;
                if (nreplies_ < kMaxReplies) {
                    Reply& r = replies_[nreplies_++];
                    r.seq = host_.seq();
                    r.msg_id = host_.msg_id();
                    r.len = host_.body_len();
                    memcpy(r.body, host_.body(), r.len);
                }
            }
        }
    }

    // No motor driven with a stop fault latched or by a halted hand; duty and PWM within the
    // configured limit; a closed-loop target within the joint limits. The limits are checked
    // right after a tick (`after_tick`): loop() may change them before the next tick applies
    // them.
    void check_motors(bool after_tick) {
        const hal::host::State& s = hal::host::state();
        FUZZ_CHECK(s.lock_errors == 0, "the firmware broke its locking or transmit rules");
        const bool halted = app::board().hand.halted();
        for (uint8_t f = 0; f < 5; ++f) {
            const finger::Finger& fg = app::board().hand.finger(f);
            const finger::Params& p = fg.params();
            for (uint8_t k = 0; k < 2; ++k) {
                const hal::MotorOut& m = s.motor[f][k];
                const bool driven = m.drive == hal::Drive::FORWARD || m.drive == hal::Drive::REVERSE;
                FUZZ_CHECK(!(driven && halted), "finger %u motor %u driven by a halted hand", f, k);
                FUZZ_CHECK(!driven || !(fg.faults() & finger::kStopFaults),
                           "finger %u motor %u driven with faults 0x%02X", f, k, fg.faults());
                FUZZ_CHECK(m.on_counts <= hal::kPwmPeriod, "finger %u motor %u: %u counts", f, k,
                           m.on_counts);
                if (driven && after_tick) {
                    // One count of rounding above max_duty's counts.
                    FUZZ_CHECK((int32_t)m.on_counts * 32768L <=
                                   ((int32_t)p.max_duty + 1) * (int32_t)hal::kPwmPeriod + 32768L,
                               "finger %u motor %u: %u counts over max_duty %d", f, k,
                               m.on_counts, p.max_duty);
                }
            }
            // STBY high with a stop fault only to short-brake after JOINT_LIMIT alone (both
            // channels BRAKE, nothing driven); never on a halted hand. Channel B brakes unless
            // the finger is rotary; after a loop() pass the outputs are still the tick's, while
            // a set_finger_config may have changed `rotary` since: B is judged after ticks.
            const uint8_t stop = (uint8_t)(fg.faults() & finger::kStopFaults);
            const bool braking = s.motor[f][0].drive == hal::Drive::BRAKE &&
                                 (s.motor[f][1].drive == hal::Drive::BRAKE ||
                                  fg.params().rotary || !after_tick);
            if (halted || (stop && !(stop == finger::JOINT_LIMIT && braking))) {
                FUZZ_CHECK(!s.stby[f], "finger %u: STBY high with faults 0x%02X (halted %d)", f,
                           fg.faults(), (int)halted);
            }
            const int16_t da = fg.duty_a() < 0 ? (int16_t)-fg.duty_a() : fg.duty_a();
            const int16_t db = fg.duty_b() < 0 ? (int16_t)-fg.duty_b() : fg.duty_b();
            if (fg.active() && after_tick) {
                FUZZ_CHECK(da <= p.max_duty && db <= p.max_duty,
                           "finger %u duties %d/%d over max_duty %d", f, fg.duty_a(),
                           fg.duty_b(), p.max_duty);
            }
            if (after_tick && (fg.mode() == finger::POSITION || fg.mode() == finger::GRASP)) {
                FUZZ_CHECK(fg.target() >= p.theta_min && fg.target() <= p.theta_max,
                           "finger %u target %d outside [%d, %d]", f, fg.target(), p.theta_min,
                           p.theta_max);
            }
        }
    }

  public:
    // The configuration changes only when a request is handled (or at boot): the harnesses
    // check it after each request's reply and after each power-on.
    void check_config() {
        FUZZ_CHECK(config::valid(app::board().cfg), "the running configuration is out of range");
    }

  private:
    // A finished save_config reads back as the running configuration, byte for byte.
    void check_saved_image() {
        config::Config back;
        const config::LoadStatus st = config::load(back);
        FUZZ_CHECK(st == config::LoadStatus::LOADED, "saved image loads as status %d", (int)st);
        FUZZ_CHECK(memcmp(&back, &app::board().cfg, sizeof back) == 0,
                   "saved image differs from the running configuration");
    }

    framing::FrameDecoder host_;
    Reply replies_[kMaxReplies];
    int nreplies_ = 0;
    bool last_seen_halted_ = false;
};

}  // namespace fuzz

#endif  // UTRF_FUZZ_BOARD_H
