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
// Cost in the tick. Every tick a moving finger advances its phase and steps its setpoint
// (a few 32-bit adds). The polynomial itself is evaluated on the finger's turn (the turn the
// hand gives its stall rule: every kStallEvery = 5 ticks, one finger a tick), for the point 5
// ticks ahead; the setpoint moves there in equal steps, and the feedforward is that point's
// (a 5 ms lead, about the motor's own lag). The straight line between two points 5 ms apart
// departs from the curve by at most h^2/8 |x''| = 3e-6 D/T^2 rad: far below a count.
// Fixed point throughout (no float, no division in the tick): tau in Q16 from a phase
// accumulator whose increment 2^32/N was worked out when the move was planned.
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

// The shortest duration the limits allow for a distance (rad, either sign), s.
float min_duration(float distance_rad, const config::Motion& m);
// Plan a move of `distance_rad` (end - start) to `end_bu` in `duration_s` (0: the shortest
// the limits allow), ticks of `dt_s`.
Plan plan(float distance_rad, float duration_s, int16_t end_bu, const config::Motion& m,
          float dt_s);

class Path {
   public:
    Path() : left_(0) {}
    bool active() const { return left_ != 0; }
    uint16_t left() const { return left_; }  // ticks to go
    int16_t feedforward() const { return ff_; }
    // Start from the setpoint `from_bu` (the finger's present one), at rest.
    void start(const Plan& p, int16_t from_bu);
    void stop() { left_ = 0; }
    // One tick: the setpoint for it in `target`, the feedforward duty (Q15) as the result.
    // `turn`: this tick evaluates the path (the finger's turn, every kEvery ticks).
    // Out of line: the hand's five finger ticks are written out, and this is their rare path.
    int16_t tick(int16_t& target, bool turn);

   private:
    void evaluate();  // on the turn: the point kEvery ticks ahead, the step toward it, ff

    uint32_t acc_;    // phase: tau = acc_ / 2^32
    uint32_t inc_;
    int32_t pos8_;    // the setpoint, BU in Q8
    int32_t step8_;   // its change a tick, BU in Q8
    int16_t start_;
    int16_t delta_;
    int16_t end_;
    int16_t cv_;
    int16_t ca_;
    int16_t ff_;
    uint16_t left_;
};

}  // namespace path
}  // namespace utrf

#endif  // UTRF_CORE_PATH_H
