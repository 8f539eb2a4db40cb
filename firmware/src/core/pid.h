// PID position controller on the Joint-2 angle, in fixed point (core/fixed.h). One
// implementation, plain C++: the AVR and the host tests run this same code.
//
//   e = target - measured
//   u = Kp e + I - Kd v + ff
//   I += Ki e dt    only while the output is not held back (by its limit or the slew
//                   limiter) in the direction e pushes it: conditional integration; and
//                   |I| <= the output limit
//   v = d(measured)/dt through a first-order low-pass (cut-off d_cutoff_hz): the derivative
//       acts on the measurement, so a target step gives no derivative kick
//   ff              a feedforward duty from whoever generates the setpoint (0 when none)
//   u += deadband * clamp(u / ramp, -1, 1)   static-friction compensation, continuous at 0
//   u = clamp(u, -limit, limit), then slew-limited to slew_per_s * dt per tick
//
// Bumpless starts: reset() makes the integrator carry the present output, and the slew limiter
// starts from it, so the output is continuous when a mode or the gains change.
//
// Fixed point, chosen so the tick is integer multiplies, byte moves and 16-bit arithmetic (no
// float, no division): angles BU (int16), e and d(measured) int16 with no overflow (angles stay
// within +-pi); v in Q8 BU per tick (int16; d(measured) is clamped to +-63 BU per tick, 12
// rad/s, beyond any finger's speed); the P and D terms int16 in Q14 duty, saturated at +-2
// duty (one 16 x 16 multiply each, the result a byte-aligned slice of the product, taken from
// the product's four 8 x 8 pieces: fixed.h, ProdSU); I in Q31 (|I| < 1 duty fits; its high
// word is the Q15 duty); u in Q15.
#ifndef UTRF_CORE_PID_H
#define UTRF_CORE_PID_H

#include <stdint.h>

#include "../generated/config_layout.h"
#include "fixed.h"

namespace utrf {
namespace pid {

// The gains as configured (config::Gains, generated from spec.toml's set_gains), ready for
// the tick. Built by compile() in loop() context (floats live there only). A gain of the law
// is a line in the spec, a field here with its line in compile(), and its use in step().
struct Coeffs {
    fx::Gain kp;          // e [BU] -> Q14 duty
    fx::Gain ki;          // e [BU] -> Q31 duty per tick
    fx::Gain kd;          // v [Q8 BU per tick] -> Q14 duty
    uint16_t alpha;       // velocity low-pass, Q16: v += alpha (x - v)
    int16_t slew;         // Q15 duty per tick
    int16_t deadband;     // Q15 duty
    uint16_t db_inverse;  // Q16: ramp / (ramp + deadband), to undo the compensation
    bool ki_plain;        // ki can never saturate: the step takes fx::apply_plain()
    // P - D's fast path: kp of shift -8 (fx::apply16_mid()) and kd of shift -16 that never
    // saturates for |v| <= kMaxV8 (fx::apply16_hi()).
    bool pd_plain;
};

// Saturation levels of the terms, chosen so no sum can overflow.
static const int16_t kTermMax14 = 32767;       // P and D terms: +-2 duty, Q14
static const int32_t kIStepMax31 = 1L << 29;  // integrator step: +-0.25 duty per tick
static const int16_t kMaxDm = 63;                // d(measured) clamp, BU per tick
static const int16_t kMaxV8 = kMaxDm * 256;      // |v|, Q8: the low-pass of 256 dm stays within
static const int16_t kDeadbandRamp15 = 256;      // 1/128 duty: the compensation ramps in

Coeffs compile(const config::Gains& g, float dt_s);
// ramp / (ramp + deadband), Q16: undoes the deadband's compensation (remove_deadband()).
uint16_t deadband_inverse(int16_t deadband);

class Pid {
   public:
    Pid();
    // Coefficients for a Pid about to be reset() (no rebase).
    void load(const Coeffs& c) { c_ = c; }
    // New gains or limit while running: keep the output where it is (the integrator absorbs the
    // change of the proportional and derivative terms).
    void set_coeffs(const Coeffs& c, int16_t new_limit);
    const Coeffs& coeffs() const { return c_; }
    // Start from the present output u (Q15) at measurement m: no bump.
    void reset(int16_t limit, int16_t u, int16_t measured);
    // One tick: returns the output, Q15, within +-limit (0 <= limit <= 32767). `ff`: a
    // feedforward duty (Q15) added ahead of the deadband, limit and slew limiter; the
    // integrator then only corrects what the feedforward misses.
    inline int16_t step(int16_t limit, int16_t target, int16_t measured, int16_t ff = 0);
    // Open loop (DUTY mode): the commanded duty through the same limit and slew limiter, so a
    // later switch to closed loop is bumpless.
    inline int16_t step_open(int16_t limit, int16_t duty, int16_t measured);

    int16_t output() const { return u_; }
    int32_t integrator31() const { return i31_; }
    int16_t velocity8() const { return v8_; }
    // The last step wanted more than the limit or slew limiter gave, toward its error.
    bool saturated() const { return saturated_; }

   private:
    // The state, then the coefficients: one object, every field within a displacement of its
    // address (the AVR's ldd/std reach 63 bytes).
    int32_t i31_;     // integrator, Q31 duty
    int16_t v8_;      // filtered d(measured), Q8 BU per tick
    int16_t m_prev_;  // last measurement, BU
    int16_t e_last_;  // last error, BU
    int16_t u_;       // last output, Q15 duty
    bool saturated_;
    Coeffs c_;
};

// The deadband compensation alone, and its inverse (for bumpless starts). Q15.
int16_t remove_deadband(int16_t u, int16_t deadband, uint16_t db_inverse);

// The per-tick functions are defined here, inline: the tick runs them five times a
// millisecond, and a call with its register saves costs as much as the arithmetic.
#define UTRF_HOT __attribute__((always_inline)) inline

// The PID's sum before the limit: |P - D| 2 + |I| + |ff| < 2^18 fits 24 bits (fx::int24).
typedef fx::int24 sum_t;

// The deadband compensation on the unlimited sum (before the limit): db added in the sum's
// direction, ramped in over |v| < kDeadbandRamp15 so it is continuous at 0.
UTRF_HOT sum_t add_deadband(sum_t v, int16_t db) {
    if (v >= kDeadbandRamp15) return v + db;
    if (v <= -kDeadbandRamp15) return v - db;
    return v + fx::prod_mid16(fx::prod_su((int16_t)v, (uint16_t)db));
}

// The integrator's general twin, out of line (pid.cpp): one copy of its 32-bit exponent
// switch in flash, not one in each of the five finger ticks.
int32_t ki_step_general(const Coeffs& c, int16_t e);

// The proportional term less the derivative one, Q14 (+-2 duty each): the law's P - D, for the
// step and for the rebase of a gain change (Pid::set_coeffs()). The fast path or its general
// twin, as compile() chose.
UTRF_HOT sum_t p_minus_d(const Coeffs& c, int16_t e, int16_t v8) {
    if (UTRF_LIKELY(c.pd_plain)) {
        return (sum_t)fx::apply16_mid(c.kp, e, kTermMax14) - fx::apply16_hi(c.kd, v8);
    }
    return (sum_t)fx::apply16(c.kp, e, kTermMax14) - fx::apply16(c.kd, v8, kTermMax14);
}

// The integrator's step, Q31: the fast path or its general twin, as compile() chose.
UTRF_HOT int32_t ki_step(const Coeffs& c, int16_t e) {
    if (UTRF_LIKELY(c.ki_plain)) return fx::apply_plain(c.ki, e);
    return ki_step_general(c, e);
}

UTRF_HOT int16_t slew_limit(int16_t want, int16_t last, int16_t slew) {
    // 16-bit only: the unsigned difference of two int16 fits, and last +- slew cannot pass
    // `want`, so it cannot overflow either.
    if (want > last) {
        if ((uint16_t)(want - last) > (uint16_t)slew) return (int16_t)(last + slew);
    } else if ((uint16_t)(last - want) > (uint16_t)slew) {
        return (int16_t)(last - slew);
    }
    return want;
}

UTRF_HOT int16_t Pid::step(int16_t limit, int16_t target, int16_t measured, int16_t ff) {
    const Coeffs& c = c_;
    // Angles are within +-pi (BU), so these differences fit int16.
    const int16_t e = (int16_t)(target - measured);
    const int16_t dm = fx::clamp16((int16_t)(measured - m_prev_), (int16_t)-kMaxDm, kMaxDm);
    m_prev_ = measured;
    e_last_ = e;
    // v += alpha (256 dm - v): |256 dm - v| < 2^15, one 16 x 16 multiply, rounded. 256 dm is a
    // multiply, not a shift: dm may be negative.
    const int16_t dv = (int16_t)(dm * 256 - v8_);
    v8_ = (int16_t)(v8_ + fx::prod_hi16(fx::prod_su(dv, c.alpha), true));

    // P - D in Q14, the integrator's high word and the feedforward in Q15: fits sum_t.
    sum_t v = p_minus_d(c, e, v8_) * 2 + (int16_t)(i31_ >> 16) + ff;
    if (c.deadband) v = add_deadband(v, c.deadband);
    // `free`: the output is the sum itself (neither the limit nor the slew limiter cut it), so
    // nothing holds it back and the test below needs no compare of the 24-bit sum.
    int16_t u;
    bool free = false;
    if (v > limit) {
        u = limit;
    } else if (v < -limit) {
        u = (int16_t)-limit;
    } else {
        u = (int16_t)v;
        free = true;
    }
    const int16_t s = slew_limit(u, u_, c.slew);
    if (s != u) free = false;
    u = s;
    u_ = u;

    // Conditional integration: hold the integrator while the output is held back in the
    // direction the error pushes it; integrate when it is free or when the error unwinds it.
    saturated_ = !free && ((v > u && e > 0) || (v < u && e < 0));
    if (!saturated_ && e != 0) {
        // min(i31 + step, limit) for a step up, max(i31 + step, -limit) for a step down, the
        // sum exact: i31 + step may overflow int32 near the limit (the add's overflow flag),
        // and the limit is a whole Q15 duty (low word 0), so the compare is of the high word.
        const int32_t step = ki_step(c, e);
        int32_t sum;
        const bool over = __builtin_add_overflow(i31_, step, &sum);
        const int16_t hi = (int16_t)(sum >> 16);
        if (step >= 0) {
            if (over || hi >= limit) sum = (int32_t)((uint32_t)(uint16_t)limit << 16);
        } else if (over || hi < -limit) {
            sum = -(int32_t)((uint32_t)(uint16_t)limit << 16);
        }
        i31_ = sum;
    }
    return u;
}

UTRF_HOT int16_t Pid::step_open(int16_t limit, int16_t duty, int16_t measured) {
    int16_t u = fx::clamp16(duty, (int16_t)-limit, limit);
    u = slew_limit(u, u_, c_.slew);
    saturated_ = u != duty;
    u_ = u;
    m_prev_ = measured;  // a switch to closed loop calls reset() with this output
    return u;
}

}  // namespace pid
}  // namespace utrf

#endif  // UTRF_CORE_PID_H
