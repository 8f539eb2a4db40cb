// The five fingers and the board-wide rules of the control tick: host silence, tick overruns,
// a hung loop(), and the tick's own timing.
//
// Concurrency: tick() runs in the timer interrupt (with other interrupts enabled). loop()
// changes fingers and settings only between hal::tick_lock() and hal::tick_unlock(), and
// reports a received frame through note_frame(), a single-byte flag the tick consumes.
#ifndef UTRF_CORE_HAND_H
#define UTRF_CORE_HAND_H

#include <stdint.h>

#include "../hal/hal.h"
#include "config.h"
#include "finger.h"

namespace utrf {
namespace hand {

static const uint8_t kFingers = 5;
static const uint16_t kTickHz = 1000;
static const float kDt = 1.0f / kTickHz;
// loop() must run at least this often, or the tick turns the motors off and the watchdog
// resets the board. Below the watchdog's 30 ms (hal/avr), so the firmware stops the motors and
// marks the hang itself first whenever its tick still runs.
static const uint16_t kLoopHangTicks = 20;

struct TickTiming {
    uint32_t ticks;
    uint32_t overruns;
    uint32_t worst_cycles;
    uint32_t mean_cycles;  // over the last complete window of 1024 ticks (0 before one)
};

class Hand {
   public:
    Hand();

    // loop() context, under the tick lock.
    void configure_finger(uint8_t f, const finger::Params& p, const pid::Coeffs& c) {
        fingers_[f].configure(p, c);
    }
    void set_safety(uint16_t timeout_ms, uint8_t safe_action);
    finger::Finger& finger(uint8_t f) { return fingers_[f]; }
    const finger::Finger& finger(uint8_t f) const { return fingers_[f]; }
    void reset_timing();
    TickTiming timing() const {
        TickTiming t = timing_;
        t.ticks = ticks_ - timing_base_;  // each tick is timed: the same count
        t.worst_cycles = worst_cycles_;
        return t;
    }

    // loop() context, no lock needed.
    void note_frame() { frame_seen_ = 1; }
    void note_loop() { loop_count_ = (uint8_t)(loop_count_ + 1); }
    bool halted() const { return halted_ != 0; }
    // Stop driving for good (until the watchdog resets the board): every motor off, every
    // finger in COAST (so the state reports what the motors do), the hang mark left for the
    // next boot; drive requests are refused from now on (proto::ErrorCode::HALTED). From the
    // tick (loop-alive rule), or from loop() under the tick lock (tick-alive rule).
    void halt() {
        halted_ = 1;
        hal::motors_all_off();
        hal::watchdog_mark_hang();
        for (uint8_t f = 0; f < kFingers; ++f) fingers_[f].halt();
    }
    uint32_t ticks() const;  // atomic read

    // The control tick (interrupt context), and its timing, measured by the caller at its end
    // (in cycles: a tick lasts at most two periods, 32,000 cycles, so 16 bits hold it).
    // Inline (below): app::tick() and tick_done() call them on the one Hand, a static object,
    // so every field of it is at a fixed address (lds/sts, no pointer).
    inline void tick(const hal::EncoderReading* enc);
    inline void record_timing(uint16_t cycles, bool overran);

   private:
    finger::Finger fingers_[kFingers];
    uint32_t ticks_;
    uint32_t last_frame_tick_;
    uint16_t timeout_ticks_;
    uint8_t safe_action_;
    bool timed_out_;
    volatile uint8_t frame_seen_;
    volatile uint8_t loop_count_;
    uint8_t loop_seen_;
    uint16_t loop_idle_ticks_;
    volatile uint8_t halted_;
    bool overrun_pending_;
    uint8_t stall_turn_;  // the finger whose stall rule runs this tick
    TickTiming timing_;     // its ticks and worst_cycles fields unused: see timing()
    uint16_t worst_cycles_;
    uint32_t timing_base_;  // ticks_ at reset_timing()
    uint32_t window_sum_;
    uint16_t window_n_;
};

UTRF_HOT void Hand::tick(const hal::EncoderReading* enc) {
    ++ticks_;

    // ---- host silence: any valid frame feeds it; the safe action once per silence ----
    if (frame_seen_) {
        frame_seen_ = 0;
        last_frame_tick_ = ticks_;
        timed_out_ = false;
    }
    if (UTRF_UNLIKELY(!timed_out_ && ticks_ - last_frame_tick_ >= timeout_ticks_)) {
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
    if (UTRF_UNLIKELY(overrun_pending_)) {
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
        halt();
    }
    if (UTRF_UNLIKELY(halted_)) {
        hal::motors_all_off();
        return;
    }

    hal::MotorCommand out[kFingers];
    const uint8_t turn = stall_turn_;
    stall_turn_ = (uint8_t)(turn + 1 == finger::kStallEvery ? 0 : turn + 1);
    // Unrolled: each finger's fields are then at fixed addresses (the Hand is a static object),
    // reached with direct loads and stores instead of through a pointer kept in registers.
    static_assert(kFingers == 5, "the finger ticks below are written out for five fingers");
    fingers_[0].tick(enc[0], out[0], turn == 0);
    fingers_[1].tick(enc[1], out[1], turn == 1);
    fingers_[2].tick(enc[2], out[2], turn == 2);
    fingers_[3].tick(enc[3], out[3], turn == 3);
    fingers_[4].tick(enc[4], out[4], turn == 4);
    hal::motors_write(out);
}

UTRF_HOT void Hand::record_timing(uint16_t cycles, bool overran) {
    if (UTRF_UNLIKELY(overran)) {
        ++timing_.overruns;
        overrun_pending_ = true;
    }
    if (cycles > worst_cycles_) worst_cycles_ = cycles;
    window_sum_ += cycles;
    if (++window_n_ == 1024) {
        timing_.mean_cycles = window_sum_ >> 10;
        window_sum_ = 0;
        window_n_ = 0;
    }
}

}  // namespace hand
}  // namespace utrf

#endif  // UTRF_CORE_HAND_H
