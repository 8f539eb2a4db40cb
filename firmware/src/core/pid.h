// PID position controller on the Joint-2 angle, in fixed point (core/fixed.h).
//
//   u = Kp e + I - D,    e = target - measured
//   I += Ki e dt         only while the output is not saturated in the direction e pushes
//                        (conditional integration), and |I| <= the output limit
//   D = filtered Kd d(measured)/dt: derivative on the measurement, so a target step gives no
//       derivative kick; first-order low-pass with cut-off d_cutoff_hz
//   u += deadband * clamp(u / ramp, -1, 1)   static-friction compensation, continuous at 0
//   u = clamp(u, -limit, limit), then slew-limited to slew_per_s * dt per tick
//
// Bumpless starts: reset() makes the integrator carry the present output, and the slew limiter
// starts from it, so the output is continuous when a mode or the gains change.
#ifndef UTRF_CORE_PID_H
#define UTRF_CORE_PID_H

#include <stdint.h>

#include "fixed.h"

namespace utrf {
namespace pid {

// SI gains, as configured (set_gains).
struct Gains {
    float kp;           // duty per rad
    float ki;           // duty per rad s
    float kd;           // duty s per rad
    float d_cutoff_hz;  // derivative filter cut-off
    float deadband;     // duty added in the output's direction
    float slew_per_s;   // largest output change per second (duty/s)
};

// The same, ready for the tick. Built by compile() in loop() context (floats live here only).
struct Coeffs {
    fx::SatGain kp;     // e [AU]  -> Q24 duty
    fx::SatGain ki;     // e [AU]  -> Q32 duty per tick (>> 8 -> Q24)
    fx::SatGain kd;     // dm [AU per tick] -> Q24 duty
    uint16_t alpha;     // derivative low-pass, Q16 (y += alpha (x - y))
    int32_t slew;       // Q16 duty per tick
    int32_t deadband;   // Q16 duty
};

static const int32_t kDeadbandRamp16 = 1024;  // 1/64 duty: the compensation ramps in over this

Coeffs compile(const Gains& g, float dt_s);

class Pid {
   public:
    Pid();
    // Start from the present output u16 (Q16) at measurement m: no bump.
    void reset(const Coeffs& c, int32_t limit16, int32_t u16, int32_t measured);
    // One tick: returns the output, Q16, within +-limit16.
    int32_t step(const Coeffs& c, int32_t limit16, int32_t target, int32_t measured);
    // Open loop (DUTY mode): the commanded duty through the same limit and slew limiter, so a
    // later switch to closed loop is bumpless.
    int32_t step_open(const Coeffs& c, int32_t limit16, int32_t duty16, int32_t measured);
    // New gains or limit: keep the output where it is (the integrator absorbs the change of
    // the proportional term; the derivative filter restarts).
    void rebase(const Coeffs& old_c, const Coeffs& new_c, int32_t new_limit16);

    int32_t output() const { return u16_; }
    int32_t integrator24() const { return i24_; }
    int32_t derivative24() const { return d24_; }
    // The last step wanted more than the limit or slew limiter gave, toward its error.
    bool saturated() const { return saturated_; }

   private:
    int32_t i24_;     // integrator, Q24 duty
    int32_t d24_;     // filtered derivative term, Q24 duty
    int32_t m_prev_;  // last measurement, AU
    int32_t e_last_;  // last error, AU
    int32_t u16_;     // last output, Q16 duty
    bool saturated_;
};

// The deadband compensation alone, and its inverse (for bumpless starts).
int32_t add_deadband(int32_t v16, int32_t deadband16);
int32_t remove_deadband(int32_t u16, int32_t deadband16);

}  // namespace pid
}  // namespace utrf

#endif  // UTRF_CORE_PID_H
