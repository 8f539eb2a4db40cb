// Moves on the board's clock: a minimum-jerk path per finger, generated in the tick, with the
// feedforward duty its speed and acceleration need.
//
//   s(tau)  = 10 tau^3 - 15 tau^4 + 6 tau^5          tau = t / T in [0, 1]
//   x(t)    = x0 + D s(tau)
//   speed   = D s'(tau) / T,   s' = 30 tau^2 (1 - tau)^2,          peak 1.875 D / T at T/2
//   accel   = D s''(tau) / T^2, s'' = 60 tau (1 - tau) (1 - 2 tau), peak 5.7735 D / T^2
//   ff      = kv speed + ka accel                      (duty; added to the PID's output)
//
// The stretching rule (plan()): a finger with limits max_speed and max_accel moving a distance
// D needs at least T_min = max(1.875 |D| / max_speed, sqrt(5.7735 |D| / max_accel)). A
// requested T below T_min is stretched to T_min (and reported); T = 0 asks for T_min. T is
// then rounded up to whole ticks.
//
// Cost in the tick. The path is cut into segments of kEvery = 5 ticks. loop() works out each
// segment's end point (the polynomial: nine 16 x 16 multiplies, too many for the tick)
// one segment ahead and hands it over under the tick lock, with the step a tick toward it
// (worked out there from where the setpoint will be when the segment starts: the present
// segment's remaining steps are fixed); every tick a moving finger only steps its setpoint
// (a 32-bit add), and at a segment's end copies the next step in. The feedforward is that of the segment's end point (a 5 ms lead, about the
// motor's own lag). The straight line between two points 5 ms apart departs from the curve
// by at most h^2/8 |x''| = 3e-6 D/T^2 rad: far below a count. Should loop() be late, the
// setpoint goes on at the same step (a tick at a time) until the next segment comes; the end
// is exact whatever happens (the last tick sets it). Fixed point throughout, in loop() too:
// tau in Q16 from a phase accumulator whose step 2^32/N was worked out when the move was
// planned.
#ifndef UTRF_CORE_PATH_H
#define UTRF_CORE_PATH_H

#include <stdint.h>

#include "config.h"
#include "fixed.h"

namespace utrf {
namespace path {

// Ticks between two evaluations of a finger's path (the hand's stall turn).
static const uint8_t kEvery = 5;
// Peaks of the normalised profile's derivatives.
static const float kPeakSpeed = 1.875f;    // max s'
static const float kPeakAccel = 5.7735f;   // max |s''| = 10 / sqrt(3)

// A planned move, ready for Path::start(): made in loop() context (floats live here only).
struct Plan {
    int16_t end;       // BU
    uint16_t ticks;    // the path's length, N >= 1
    uint32_t inc;      // 2^32 / N, the phase step a tick
    int16_t cv;        // feedforward duty at the path's peak speed, Q15, signed like D
    int16_t ca;        // ... at its peak acceleration, Q15, signed like D
    bool stretched;    // the requested duration was below what the limits allow
};

// A finger's motion limits and feedforward gains, compiled from config::Motion when its
// configuration changes (loop() context), so that planning a move takes one float division
// and at most one square root a finger (about 0.3 ms on the AVR for five: a longer loop()
// pass would hold the state stream up).
struct Limits {
    float speed_ticks;  // ticks a radian needs at the peak speed: 1.875 / (max_speed dt)
    float accel_ticks;  // ticks^2 a radian needs at the peak acceleration: 5.7735 / (max_accel dt^2)
    float cv;           // feedforward Q15 at the peak speed of a path of D rad in N ticks: cv D / N
    float ca;           // ... at its peak acceleration: ca D / N^2
    float ticks_per_s;  // 1 / dt
};
Limits compile(const config::Motion& m, float dt_s);
// The shortest duration the limits allow for a distance (rad, either sign), s.
float min_duration(float distance_rad, const config::Motion& m);
// Plan a move of `distance_rad` (end - start) to `end_bu` in `duration_s` (0: the shortest
// the limits allow).
Plan plan(float distance_rad, float duration_s, int16_t end_bu, const Limits& k);

class Path {
   public:
    Path() : left_(0), seg_left_(0), next_ready_(0), plan_left_(0) {}
    bool active() const { return left_ != 0; }
    uint16_t left() const { return left_; }  // ticks to go
    int16_t end() const { return end_; }      // BU: where it ends (valid while active())
    int16_t feedforward() const { return ff_; }
    // loop() context, under the tick lock: start from the setpoint `from_bu` (the finger's
    // present one), at rest. Cheap: plan_next() works out the first segment.
    // `first`: the first segment's length, 1..kEvery (the hand staggers its fingers' segment
    // ends, so their segments are not all taken in the same tick).
    void start(const Plan& p, int16_t from_bu, uint8_t first);
    // Ends the path and its planning (the tick's or loop()'s: plan_next_work() writes
    // plan_left_ only while left_ != 0, under the lock, so no segment is planned after this).
    void stop() {
        left_ = 0;
        plan_left_ = 0;
    }
    // loop() context: segments still to work out (loop() is woken every tick meanwhile).
    bool planning() const { return plan_left_ != 0; }
    // loop() context, without the lock (it takes it to hand the segment over): work out the
    // next segment when the tick has taken the last one. Cheap when there is nothing to do:
    // that test inline (loop() runs it for every finger every pass; the work's frame is not).
    void plan_next() {
        if (plan_left_ != 0 && !next_ready_) plan_next_work();
    }
    void plan_next_work();  // plan_next()'s work, out of line
    // The tick: the setpoint for it in `target`, the feedforward duty (Q15) as the result.
    inline int16_t tick(int16_t& target);

   private:
    // The tick, at a segment's end: take the one loop() worked out, its step included (inline:
    // a call with its register saves cost more than the copy, and in the worst tick several
    // fingers take theirs).
    inline void next_segment();
    // The path's point `ahead` ticks after the phase `acc` (the end for the last segment),
    // and the feedforward there.
    void evaluate(uint32_t acc, uint16_t left_after, int16_t& goal, int16_t& ff) const;

    // ---- the tick's ----
    // 24 bits (fx::int24): the setpoint is within +-pi (|pos8| <= 2^22), a step at most the
    // distance of a segment (|goal - at| < 2^15 BU) and in practice max_speed (<= 100 rad/s,
    // 521 BU a tick) allows; a late loop() carries the setpoint on by a step a tick for at
    // most kLoopHangTicks (20) ticks, 2^14 BU more at worst: |pos8| < 2^23 throughout.
    fx::int24 pos8_;    // the setpoint, BU in Q8
    fx::int24 step8_;   // its change a tick, BU in Q8
    int16_t ff_;
    int16_t end_;
    uint16_t left_;      // ticks to the path's end; 0: no path
    uint8_t seg_left_;   // ticks left in this segment; 0: take the next one
    // ---- the next segment, from loop(): taken by the tick at the segment's end ----
    fx::int24 next_step8_;
    int16_t next_ff_;
    uint8_t next_len_;
    volatile uint8_t next_ready_;
    // ---- loop()'s: the path's constants and where its planning is ----
    uint32_t inc_;
    uint32_t plan_acc_;   // phase at the end of the last segment worked out
    uint16_t plan_left_;  // ticks of the path after that segment
    uint8_t plan_n_;      // the next segment's length: kEvery, or the first one's
    int16_t start_;
    int16_t delta_;
    int16_t cv_;
    int16_t ca_;
};

// 65536 / n for the steps toward a point n ticks ahead (n <= kEvery).
extern const uint16_t kRecip[kEvery + 1];

__attribute__((always_inline)) inline void Path::next_segment() {
    // A straight step to the path's point at the segment's end, worked out by loop() with the
    // segment. Without one (loop() late), the same step goes on for another tick.
    if (UTRF_LIKELY(next_ready_)) {
        step8_ = next_step8_;
        ff_ = next_ff_;
        seg_left_ = next_len_;
        next_ready_ = 0;
    } else {
        seg_left_ = 1;
    }
}

__attribute__((always_inline)) inline int16_t Path::tick(int16_t& target) {
    if (--left_ == 0) {  // the end: exactly there, at rest
        target = end_;
        ff_ = 0;
        return 0;
    }
    if (UTRF_UNLIKELY(seg_left_ == 0)) next_segment();
    --seg_left_;
    pos8_ += step8_;
    target = (int16_t)(pos8_ >> 8);
    return ff_;
}

}  // namespace path
}  // namespace utrf

#endif  // UTRF_CORE_PATH_H
