#include "pid.h"

#include <math.h>

namespace utrf {
namespace pid {

namespace {
const float kRadPerBu = 1.0f / fx::kBuPerRad;

int16_t q15(float duty) { return fx::sat16(fx::round_sat(duty * 32768.0f)); }
}  // namespace

Coeffs compile(const config::Gains& g, float dt_s) {
    Coeffs c = Coeffs();
    c.kp = fx::make_gain(g.kp * kRadPerBu * 16384.0f, kTermMax14);
    c.ki = fx::make_gain(g.ki * dt_s * kRadPerBu * 2147483648.0f, kIStepMax31);
    c.ki_plain = fx::plain(c.ki, kIStepMax31);
    // v is Q8 BU per tick: rad/s = v / 256 * kRadPerBu / dt.
    c.kd = fx::make_gain(g.kd * kRadPerBu / (256.0f * dt_s) * 16384.0f, kTermMax14);
    c.pd_plain = fx::mid16(c.kp) && fx::hi16_plain(c.kd, kMaxV8);
    // Matched pole of a first-order low-pass: alpha = 1 - exp(-2 pi fc dt).
    const float a = 1.0f - expf(-2.0f * 3.14159265f * g.d_cutoff_hz * dt_s);
    c.alpha = (uint16_t)fx::clamp32(fx::round_sat(a * 65536.0f), 1, 65535);
    c.slew = (int16_t)fx::clamp32(fx::round_sat(g.slew_per_s * dt_s * 32768.0f), 1, 32767);
    c.deadband = (int16_t)fx::clamp32(
        q15(g.deadband_duty * proto::SetGains::kDeadbandDutyScale), 0, 16384);
    c.db_inverse = deadband_inverse(c.deadband);
    return c;
}

uint16_t deadband_inverse(int16_t deadband) {
    return (uint16_t)fx::clamp32(
        fx::round_sat(65536.0f * kDeadbandRamp15 / (float)(kDeadbandRamp15 + deadband)), 0,
        65535);
}

int16_t remove_deadband(int16_t u, int16_t db, uint16_t db_inverse) {
    if (db == 0) return u;
    const int16_t edge = (int16_t)(kDeadbandRamp15 + db);
    if (u >= edge) return (int16_t)(u - db);
    if (u <= -edge) return (int16_t)(u + db);
    return (int16_t)(((int32_t)u * db_inverse) >> 16);
}

int32_t ki_step_general(const Coeffs& c, int16_t e) { return fx::apply(c.ki, e, kIStepMax31); }

Pid::Pid() : i31_(0), v8_(0), m_prev_(0), e_last_(0), u_(0), saturated_(false), c_() {}

void Pid::reset(int16_t limit, int16_t u, int16_t measured) {
    u_ = fx::clamp16(u, (int16_t)-limit, limit);
    const int16_t v = fx::clamp16(remove_deadband(u_, c_.deadband, c_.db_inverse),
                                  (int16_t)-limit, limit);
    i31_ = (int32_t)((uint32_t)(int32_t)v << 16);
    v8_ = 0;
    m_prev_ = measured;
    e_last_ = 0;
    saturated_ = false;
}

void Pid::set_coeffs(const Coeffs& c, int16_t new_limit) {
    // The output before the change, less the new P and D terms, is the new integrator.
    const int32_t before = (int32_t)p_minus_d(c_, e_last_, v8_) * 2 + (int16_t)(i31_ >> 16);
    c_ = c;
    const int32_t i15 =
        fx::clamp32(before - (int32_t)p_minus_d(c, e_last_, v8_) * 2, -new_limit, new_limit);
    i31_ = (int32_t)((uint32_t)i15 << 16);
    u_ = fx::clamp16(u_, (int16_t)-new_limit, new_limit);
}

}  // namespace pid
}  // namespace utrf
