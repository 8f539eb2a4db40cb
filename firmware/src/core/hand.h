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
// resets the board.
static const uint16_t kLoopHangTicks = 50;

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
    void configure_finger(uint8_t f, const finger::Params& p) { fingers_[f].configure(p); }
    void set_safety(uint16_t timeout_ms, uint8_t safe_action);
    finger::Finger& finger(uint8_t f) { return fingers_[f]; }
    const finger::Finger& finger(uint8_t f) const { return fingers_[f]; }
    void reset_timing();
    TickTiming timing() const { return timing_; }

    // loop() context, no lock needed.
    void note_frame() { frame_seen_ = 1; }
    void note_loop() { loop_count_ = (uint8_t)(loop_count_ + 1); }
    bool halted() const { return halted_ != 0; }
    uint32_t ticks() const;  // atomic read

    // The control tick (interrupt context). `cycles_prev`/`overran_prev` time the previous
    // tick, measured by the caller at its end.
    void tick(const hal::EncoderReading* enc);
    void record_timing(uint32_t cycles, bool overran);

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
    TickTiming timing_;
    uint32_t window_sum_;
    uint16_t window_n_;
};

}  // namespace hand
}  // namespace utrf

#endif  // UTRF_CORE_HAND_H
