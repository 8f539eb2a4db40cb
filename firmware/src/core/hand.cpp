#include "hand.h"

namespace utrf {
namespace hand {

Hand::Hand()
    : ticks_(0),
      last_frame_tick_(0),
      timeout_ticks_(500),
      safe_action_(0),
      timed_out_(false),
      frame_seen_(0),
      loop_count_(0),
      loop_seen_(0),
      loop_idle_ticks_(0),
      halted_(0),
      overrun_pending_(false),
      stall_turn_(0),
      window_sum_(0),
      window_n_(0) {
    timing_.ticks = 0;
    timing_.overruns = 0;
    timing_.worst_cycles = 0;
    timing_.mean_cycles = 0;
}

void Hand::set_safety(uint16_t timeout_ms, uint8_t safe_action) {
    timeout_ticks_ = (uint16_t)(((uint32_t)timeout_ms * kTickHz + 999u) / 1000u);
    safe_action_ = safe_action;
}

void Hand::reset_timing() {
    timing_.ticks = 0;
    timing_.overruns = 0;
    timing_.worst_cycles = 0;
    timing_.mean_cycles = 0;
    window_sum_ = 0;
    window_n_ = 0;
}

uint32_t Hand::ticks() const {
    const volatile uint32_t* p = &ticks_;
    uint32_t a, b;
    do {
        a = *p;
        b = *p;
    } while (a != b);
    return a;
}

void Hand::tick(const hal::EncoderReading* enc) {
    ++ticks_;

    // ---- host silence: any valid frame feeds it; the safe action once per silence ----
    if (frame_seen_) {
        frame_seen_ = 0;
        last_frame_tick_ = ticks_;
        timed_out_ = false;
    }
    if (!timed_out_ && ticks_ - last_frame_tick_ >= timeout_ticks_) {
        timed_out_ = true;
        for (uint8_t f = 0; f < kFingers; ++f) {
            finger::Finger& fg = fingers_[f];
            if (!fg.active()) continue;  // nothing runs unsupervised on an idle finger
            fg.latch(finger::HOST_TIMEOUT);
            if (safe_action_ == 0) {  // proto::SafeAction::HOLD
                fg.hold_here();
            } else {
                fg.set_mode(finger::COAST, 0, 0);
            }
        }
    }

    // ---- the previous tick overran: every finger stops ----
    if (overrun_pending_) {
        overrun_pending_ = false;
        for (uint8_t f = 0; f < kFingers; ++f) fingers_[f].latch(finger::OVERRUN);
    }

    // ---- loop() must keep running; if it hangs the watchdog is about to reset us ----
    const uint8_t lc = loop_count_;
    if (lc != loop_seen_) {
        loop_seen_ = lc;
        loop_idle_ticks_ = 0;
    } else if (loop_idle_ticks_ < kLoopHangTicks) {
        ++loop_idle_ticks_;
    } else if (!halted_) {
        halted_ = 1;
        hal::watchdog_mark_hang();
    }
    if (halted_) {
        hal::motors_all_off();
        return;
    }

    hal::MotorCommand out[kFingers];
    const uint8_t turn = stall_turn_;
    stall_turn_ = (uint8_t)(turn + 1 == finger::kStallEvery ? 0 : turn + 1);
    for (uint8_t f = 0; f < kFingers; ++f) fingers_[f].tick(enc[f], out[f], f == turn);
    hal::motors_write(out);
}

void Hand::record_timing(uint32_t cycles, bool overran) {
    ++timing_.ticks;
    if (overran) {
        ++timing_.overruns;
        overrun_pending_ = true;
    }
    if (cycles > timing_.worst_cycles) timing_.worst_cycles = cycles;
    window_sum_ += cycles;
    if (++window_n_ == 1024) {
        timing_.mean_cycles = window_sum_ >> 10;
        window_sum_ = 0;
        window_n_ = 0;
    }
}

}  // namespace hand
}  // namespace utrf
