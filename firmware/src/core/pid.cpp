#include "pid.h"

#include <math.h>

namespace utrf {
namespace pid {

namespace {
// Saturation levels of the terms, chosen so no sum can overflow int32 in Q24.
const int32_t kPMax24 = 8L * fx::kOne24;        // proportional term: +-8 duty
const int32_t kIStepMax32 = 64L * fx::kOne24;   // integrator step: +-0.25 duty per tick (Q32)
const int32_t kDMax24 = 4L * fx::kOne24;        // derivative term: +-4 duty
const float kQ24 = 16777216.0f;
const float kQ32 = 4294967296.0f;
const float kRadPerAu = 1e-4f;

int32_t clamp_sym(int32_t v, int32_t lim) { return fx::clamp(v, -lim, lim); }
}  // namespace

Coeffs compile(const Gains& g, float dt_s) {
    Coeffs c;
    c.kp = fx::make_sat_gain(g.kp * kRadPerAu * kQ24, kPMax24);
    c.ki = fx::make_sat_gain(g.ki * dt_s * kRadPerAu * kQ32, kIStepMax32);
    c.kd = fx::make_sat_gain(g.kd / dt_s * kRadPerAu * kQ24, kDMax24);
    // Matched pole of a first-order low-pass: alpha = 1 - exp(-2 pi fc dt).
    float a = 1.0f - expf(-2.0f * 3.14159265f * g.d_cutoff_hz * dt_s);
    int32_t a16 = fx::round_sat(a * 65536.0f);
    c.alpha = (uint16_t)fx::clamp(a16, 1, 65535);
    c.slew = fx::clamp(fx::round_sat(g.slew_per_s * dt_s * 65536.0f), 1, fx::kOne16 * 2);
    c.deadband = fx::clamp(fx::round_sat(g.deadband * 65536.0f), 0, fx::kOne16);
    return c;
}

int32_t add_deadband(int32_t v16, int32_t db16) {
    if (db16 == 0) return v16;
    if (v16 >= kDeadbandRamp16) return v16 + db16;
    if (v16 <= -kDeadbandRamp16) return v16 - db16;
    // |v16| < 2^10 and db16 <= 2^16: the product fits.
    return v16 + ((v16 * db16) >> 10);
}

int32_t remove_deadband(int32_t u16, int32_t db16) {
    if (db16 == 0) return u16;
    const int32_t edge = kDeadbandRamp16 + db16;
    if (u16 >= edge) return u16 - db16;
    if (u16 <= -edge) return u16 + db16;
    return (u16 * kDeadbandRamp16) / edge;
}

Pid::Pid() : i24_(0), d24_(0), m_prev_(0), e_last_(0), u16_(0), saturated_(false) {}

void Pid::reset(const Coeffs& c, int32_t limit16, int32_t u16, int32_t measured) {
    u16_ = clamp_sym(u16, limit16);
    i24_ = clamp_sym(remove_deadband(u16_, c.deadband), limit16) << 8;
    d24_ = 0;
    m_prev_ = measured;
    e_last_ = 0;
    saturated_ = false;
}

void Pid::rebase(const Coeffs& old_c, const Coeffs& new_c, int32_t new_limit16) {
    const int32_t p_old = fx::sat_mul(old_c.kp, e_last_);
    const int32_t p_new = fx::sat_mul(new_c.kp, e_last_);
    i24_ = clamp_sym(p_old + i24_ - d24_ - p_new, new_limit16 << 8);
    d24_ = 0;
    u16_ = clamp_sym(u16_, new_limit16);
}

int32_t Pid::step(const Coeffs& c, int32_t limit16, int32_t target, int32_t measured) {
    const int32_t e = target - measured;
    e_last_ = e;
    const int32_t p24 = fx::sat_mul(c.kp, e);
    const int32_t d_raw24 = fx::sat_mul(c.kd, measured - m_prev_);
    m_prev_ = measured;
    d24_ += fx::mul_q16(d_raw24 - d24_, c.alpha);

    // Q24 sum (|p| <= 8, |i| <= 1, |d| <= 4 duty) to Q16.
    int32_t v16 = fx::shr_round(p24 + i24_ - d24_, 8);
    v16 = add_deadband(v16, c.deadband);
    int32_t u16 = clamp_sym(v16, limit16);
    u16 = fx::clamp(u16, u16_ - c.slew, u16_ + c.slew);
    u16_ = u16;

    // Conditional integration: hold the integrator while the output is held back in the
    // direction the error pushes it; integrate when it is free or when the error unwinds it.
    const bool held_up = v16 > u16 && e > 0;
    const bool held_down = v16 < u16 && e < 0;
    saturated_ = held_up || held_down;
    if (!saturated_) {
        const int32_t step32 = fx::sat_mul(c.ki, e);
        i24_ = clamp_sym(i24_ + fx::shr_round(step32, 8), limit16 << 8);
    }
    return u16;
}

int32_t Pid::step_open(const Coeffs& c, int32_t limit16, int32_t duty16, int32_t measured) {
    int32_t u16 = clamp_sym(duty16, limit16);
    u16 = fx::clamp(u16, u16_ - c.slew, u16_ + c.slew);
    saturated_ = u16 != duty16;
    u16_ = u16;
    m_prev_ = measured;  // a switch to closed loop calls reset() with this output
    return u16;
}

}  // namespace pid
}  // namespace utrf
