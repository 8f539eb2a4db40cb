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

// One state-stream sample, taken by the tick when a frame falls due (the stream's phase runs
// on the tick), so a frame carries its own tick's values however late loop() sends it.
struct StateSample {
    uint16_t tick;  // board time, ms (wraps)
    uint8_t skipped;  // samples dropped just before this one (the ring was full)
    int16_t theta[kFingers];
    int16_t target[kFingers];
    int16_t duty_a[kFingers];  // Q15, as the finger has them: loop() turns them into the
    int16_t duty_b[kFingers];  // state message's 1/128 counts (fx::duty_counts) as it writes
};
// Samples waiting for loop(): loop() may fall this many periods behind (a long request, a
// busy line: a move's, firmware/README.md, Protocol notes) before one is dropped.
static const uint8_t kStreamSlots = 8;

class Hand {
   public:
    Hand();

    // loop() context, under the tick lock.
    // True when the new limits ended the finger's path (Finger::configure()).
    bool configure_finger(uint8_t f, const finger::Params& p, const pid::Coeffs& c) {
        const bool ended = fingers_[f].configure(p, c);
        hal::encoder_setup(f, fingers_[f].encoder_setup());  // the sampler judges with it
        return ended;
    }
    void set_safety(uint16_t timeout_ms, uint8_t safe_action);
    finger::Finger& finger(uint8_t f) { return fingers_[f]; }
    // loop() context, every pass, without the lock: the moves' next path segments; true while
    // a finger's move has segments left to work out.
    bool plan_paths() {
        bool planning = false;
        for (uint8_t f = 0; f < kFingers; ++f) planning = fingers_[f].plan_path() || planning;
        return planning;
    }
    const finger::Finger& finger(uint8_t f) const { return fingers_[f]; }
    // loop() context, every pass, without the lock (it takes it for a check): each finger's
    // stall rule about every kStallEvery ticks, counting the ticks that passed since its last
    // check (a late loop() delays a stop by its lateness, at most kLoopHangTicks).
    void stall_rules();
    void reset_timing();
    TickTiming timing() const {
        TickTiming t = timing_;
        t.ticks = ticks_ - timing_base_;  // each tick is timed: the same count
        t.worst_cycles = worst_cycles_;
        return t;
    }

    // loop() context, no lock needed.
    void note_frame() { frame_seen_ = 1; }
    // loop() context, under the tick lock: the host said goodbye (proto::Goodbye): the
    // host-silence rule stands down (0: fallen) until the next frame arms it again.
    void host_left() {
        frame_seen_ = 0;
        silence_left_ = 0;
    }
    void note_loop() { loop_count_ = (uint8_t)(loop_count_ + 1); }
    // The host-silence tick's general path instead of its fast one (the test comparing them).
    void use_general_safe_action(bool on) { safe_action_general_ = on; }
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

    // ---- the state stream's samples ----
    // loop() context, under the tick lock: the rate (0: off); clears the samples waiting.
    void set_stream(uint16_t hz) {
        stream_hz_ = hz;
        stream_acc_ = 0;
        stream_head_ = stream_tail_ = 0;
        stream_skip_ = 0;
        stream_put_ = stream_;
    }
    // loop() context, no lock: the samples waiting, the oldest, and its release.
    uint8_t stream_pending() const { return (uint8_t)(stream_head_ - stream_tail_); }
    const StateSample& stream_oldest() const { return stream_[stream_tail_ % kStreamSlots]; }
    void stream_pop() { stream_tail_ = (uint8_t)(stream_tail_ + 1); }
    // The tick, after the fingers: a sample when one falls due.
    inline void stream_tick();

    // The control tick (interrupt context), and its timing, measured by the caller at its end
    // (in cycles: a tick lasts at most two periods, 32,000 cycles, so 16 bits hold it).
    // Inline (below): app::tick() and tick_done() call them on the one Hand, a static object,
    // so every field of it is at a fixed address (lds/sts, no pointer).
    inline void tick(const hal::EncoderReading* enc);
    inline void record_timing(uint16_t cycles, bool overran);
    inline void sample_finger(StateSample& s, uint8_t f) const;
    // The tick at the host-silence timeout: each finger's Finger::tick_safe_action() in place
    // of its law step (out of line: once per silence); the fast path unless the general one
    // (the law's step as well) is chosen, for the test that compares the two.
    void safe_action_tick(const hal::EncoderReading* enc);

   private:
    // stall_rules()' checks of the fingers in `due` (bit f: finger f), in order, each under
    // the tick lock. Out of line: the passes with none due do not set up its registers.
    __attribute__((noinline)) void stall_checks(uint8_t now, uint8_t due);

    finger::Finger fingers_[kFingers];
    uint32_t ticks_;
    uint16_t silence_left_;  // ticks until the host-silence timeout; 0: timed out
    uint16_t timeout_ticks_;  // >= 1 (heartbeat_timeout >= 50 ms)
    uint8_t safe_action_;
    volatile uint8_t frame_seen_;
    volatile uint8_t loop_count_;
    uint8_t loop_seen_;
    uint16_t loop_idle_ticks_;
    volatile uint8_t halted_;
    bool overrun_pending_;
    uint8_t stall_seen_;              // ticks_' low byte at stall_rules()' last look
    uint8_t stall_at_[kFingers];      // ... at each finger's last stall check
    TickTiming timing_;     // its ticks and worst_cycles fields unused: see timing()
    uint16_t worst_cycles_;
    uint32_t timing_base_;  // ticks_ at reset_timing()
    uint32_t window_sum_;
    uint16_t window_n_;
    StateSample stream_[kStreamSlots];
    uint16_t stream_hz_;
    uint16_t stream_acc_;  // += rate a tick; a sample per kTickHz
    volatile uint8_t stream_head_;  // written by the tick
    volatile uint8_t stream_tail_;  // written by loop()
    uint8_t stream_skip_;
    StateSample* stream_put_;  // the slot stream_head_ names: the next sample's
    bool safe_action_general_;
};

UTRF_HOT void Hand::tick(const hal::EncoderReading* enc) {
    ++ticks_;

    // ---- host silence: any valid frame feeds it; the safe action once per silence ----
    // A countdown from the last frame's tick: the timeout falls timeout_ticks_ ticks after it
    // (0: fallen, until the next frame). The fingers take the safe action in this tick, after
    // the rules below (safe_action_tick()).
    bool timed_out = false;
    if (frame_seen_) {
        frame_seen_ = 0;
        silence_left_ = timeout_ticks_;
    } else if (UTRF_UNLIKELY(silence_left_ != 0 && --silence_left_ == 0)) {
        timed_out = true;
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
    if (UTRF_UNLIKELY(timed_out)) {
        safe_action_tick(enc);
        return;
    }

    // Five written-out ticks, not a loop: each Finger's fields at a fixed address (lds/sts),
    // no pointer kept and spilled (firmware/README.md, Timing). Each finger's driver command
    // goes to its driver as soon as it is worked out, from registers (hal/avr/motors_inline.h).
    static_assert(kFingers == 5, "five finger ticks written out");
    hal::MotorCommand out;
    fingers_[0].tick(enc[0], out);
    hal::motor_write<0>(out);
    fingers_[1].tick(enc[1], out);
    hal::motor_write<1>(out);
    fingers_[2].tick(enc[2], out);
    hal::motor_write<2>(out);
    fingers_[3].tick(enc[3], out);
    hal::motor_write<3>(out);
    fingers_[4].tick(enc[4], out);
    hal::motor_write<4>(out);
}

UTRF_HOT void Hand::stream_tick() {
    if (stream_hz_ == 0) return;
    uint16_t acc = (uint16_t)(stream_acc_ + stream_hz_);
    if (acc < kTickHz) {
        stream_acc_ = acc;
        return;
    }
    stream_acc_ = (uint16_t)(acc - kTickHz);
    const uint8_t head = stream_head_;
    if (UTRF_UNLIKELY((uint8_t)(head - stream_tail_) >= kStreamSlots)) {
        if (stream_skip_ != 0xFF) ++stream_skip_;  // full: this sample is dropped
        return;
    }
    // The slot is kept as a pointer (stream_put_), not worked out from head: the compiler
    // would work out the slot's address (head * 43) anew for each field it writes.
    StateSample& s = *stream_put_;
    s.tick = (uint16_t)ticks_;
    s.skipped = stream_skip_;
    stream_skip_ = 0;
    // Written out: each finger's fields at a fixed address (the Hand is one static object).
    sample_finger(s, 0);
    sample_finger(s, 1);
    sample_finger(s, 2);
    sample_finger(s, 3);
    sample_finger(s, 4);
    const uint8_t next = (uint8_t)(head + 1);
    stream_put_ = (next % kStreamSlots) == 0 ? stream_ : stream_put_ + 1;
    stream_head_ = next;
}

UTRF_HOT void Hand::sample_finger(StateSample& s, uint8_t f) const {
    const finger::Finger& fg = fingers_[f];
    s.theta[f] = fg.theta();
    s.target[f] = fg.target();
    s.duty_a[f] = fg.duty_a();
    s.duty_b[f] = fg.duty_b();
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
