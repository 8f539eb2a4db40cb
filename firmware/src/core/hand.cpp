#include "hand.h"

namespace utrf {
namespace hand {

Hand::Hand()
    : ticks_(0),
      silence_left_(500),
      timeout_ticks_(500),
      safe_action_(0),
      frame_seen_(0),
      loop_count_(0),
      loop_seen_(0),
      loop_idle_ticks_(0),
      halted_(0),
      overrun_pending_(false),
      stall_seen_(0),
      worst_cycles_(0),
      timing_base_(0),
      window_sum_(0),
      window_n_(0),
      stream_hz_(0),
      stream_acc_(0),
      stream_head_(0),
      stream_tail_(0),
      stream_skip_(0),
      stream_put_(stream_),
      safe_action_general_(false) {
    timing_.ticks = 0;
    timing_.overruns = 0;
    timing_.worst_cycles = 0;
    timing_.mean_cycles = 0;
    // Staggered: one finger's check a tick where loop() runs every tick (the host tests); on
    // the board, which wakes loop() every kLoopEveryTicks (core/app.h), they fall due together
    // after the first pass.
    for (uint8_t f = 0; f < kFingers; ++f) stall_at_[f] = f;
}

void Hand::stall_rules() {
    // The tick count's low byte alone, read whole (one byte: no torn read, no retry).
    static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the low byte comes first");
    const uint8_t now = *reinterpret_cast<const volatile uint8_t*>(&ticks_);
    if (now == stall_seen_) return;
    stall_seen_ = now;
    // Which fingers are due, with no call in the loop (its counters need no saving); then
    // their checks (usually one finger's a tick).
    uint8_t due = 0;
    uint8_t bit = 1;
    for (uint8_t f = 0; f < kFingers; ++f, bit = (uint8_t)(bit << 1)) {
        if ((uint8_t)(now - stall_at_[f]) >= finger::kStallEvery) due |= bit;
    }
    if (due != 0) stall_checks(now, due);
}

void Hand::stall_checks(uint8_t now, uint8_t due) {
    // Under one lock (usually all five are due together, loop() being woken every
    // kLoopEveryTicks ticks): some 350 cycles at most that a tick may wait.
    hal::tick_lock();
    uint8_t bit = 1;
    for (uint8_t f = 0; f < kFingers; ++f, bit = (uint8_t)(bit << 1)) {
        if (!(due & bit)) continue;
        const uint8_t elapsed = (uint8_t)(now - stall_at_[f]);
        stall_at_[f] = now;
        if (fingers_[f].stall_rule(elapsed)) hal::motor_off(f);  // stopped now, not next tick
    }
    hal::tick_unlock();
}

void Hand::safe_action_tick(const hal::EncoderReading* enc) {
    const bool hold = safe_action_ == 0;  // proto::SafeAction::HOLD
    const bool step_law = safe_action_general_;
    hal::MotorCommand out;
    static_assert(kFingers == 5, "five finger ticks written out");
    fingers_[0].tick_safe_action(enc[0], out, hold, step_law);
    hal::motor_write<0>(out);
    fingers_[1].tick_safe_action(enc[1], out, hold, step_law);
    hal::motor_write<1>(out);
    fingers_[2].tick_safe_action(enc[2], out, hold, step_law);
    hal::motor_write<2>(out);
    fingers_[3].tick_safe_action(enc[3], out, hold, step_law);
    hal::motor_write<3>(out);
    fingers_[4].tick_safe_action(enc[4], out, hold, step_law);
    hal::motor_write<4>(out);
}

void Hand::set_safety(uint16_t timeout_ms, uint8_t safe_action) {
    timeout_ticks_ = (uint16_t)(((uint32_t)timeout_ms * kTickHz + 999u) / 1000u);
    if (timeout_ticks_ == 0) timeout_ticks_ = 1;
    safe_action_ = safe_action;
}

void Hand::reset_timing() {
    timing_.ticks = 0;
    worst_cycles_ = 0;
    timing_base_ = ticks_;
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

}  // namespace hand
}  // namespace utrf
