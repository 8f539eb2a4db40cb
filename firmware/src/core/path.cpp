#include "path.h"

#include <math.h>

#include "../hal/hal.h"

namespace utrf {
namespace path {

const uint16_t kRecip[kEvery + 1] = {0, 65535u, 32768u, 21845u, 16384u, 13107u};

namespace {
inline uint16_t hi16(uint32_t v) { return (uint16_t)(v >> 16); }
}  // namespace

Limits compile(const config::Motion& m, float dt_s) {
    Limits k;
    k.ticks_per_s = 1.0f / dt_s;
    k.speed_ticks = kPeakSpeed / (m.max_speed * dt_s);
    k.accel_ticks = kPeakAccel / (m.max_accel * dt_s * dt_s);
    k.cv = m.kv * kPeakSpeed * 32768.0f / dt_s;
    k.ca = m.ka * kPeakAccel * 32768.0f / (dt_s * dt_s);
    return k;
}

float min_duration(float distance_rad, const config::Motion& m) {
    const float d = fabsf(distance_rad);
    const float tv = kPeakSpeed * d / m.max_speed;
    const float ta = sqrtf(kPeakAccel * d / m.max_accel);
    return tv > ta ? tv : ta;
}

Plan plan(float distance_rad, float duration_s, int16_t end_bu, const Limits& k) {
    Plan p;
    p.end = end_bu;
    // The shortest path in ticks: max(speed_ticks d, sqrt(accel_ticks d)), the square root
    // only when the acceleration is the bound.
    const float d = fabsf(distance_rad);
    const float nv = k.speed_ticks * d;
    const float na2 = k.accel_ticks * d;
    const float n_min = nv * nv >= na2 ? nv : sqrtf(na2);
    float n = duration_s * k.ticks_per_s;
    p.stretched = false;
    if (!(n > 0.0f)) {
        n = n_min;
    } else if (n_min > n + 0.5f) {  // within half a tick of the request is no stretch
        n = n_min;
        p.stretched = true;
    }
    n = ceilf(n - 1e-3f);
    if (n < 1.0f) n = 1.0f;
    if (n > 65535.0f) n = 65535.0f;
    p.ticks = (uint16_t)n;
    p.inc = 0xFFFFFFFFUL / p.ticks;
    const float inv = 1.0f / n;  // the one division
    const float r = distance_rad * inv;
    p.cv = fx::sat16(fx::round_sat(k.cv * r));
    p.ca = fx::sat16(fx::round_sat(k.ca * r * inv));
    return p;
}

void Path::start(const Plan& p, int16_t from_bu, uint8_t first) {
    // Cheap: this runs under the tick lock. The first segment is loop()'s (plan_next(), at
    // once after the move's reply): until it comes the setpoint stands, at rest as the path
    // starts.
    start_ = from_bu;
    end_ = p.end;
    delta_ = (int16_t)(p.end - from_bu);  // both within +-pi: fits
    inc_ = p.inc;
    cv_ = p.cv;
    ca_ = p.ca;
    pos8_ = (fx::int24)((int32_t)from_bu * 256);  // Q8 (a multiply: a left shift of a negative is UB)
    step8_ = 0;
    ff_ = 0;
    left_ = p.ticks;
    seg_left_ = 0;
    next_ready_ = 0;
    plan_acc_ = 0;
    plan_left_ = p.ticks;
    plan_n_ = (first < 1 || first > kEvery) ? kEvery : first;
}

void Path::plan_next_work() {
    // Only loop() writes the planning fields and sets next_ready_; the tick clears it and
    // stop() ends the path: read the flag and the path's state under the lock.
    // Without the lock first (plan_next(), inline): plan_left_ is loop()'s own and next_ready_
    // a byte, and most passes have nothing to do.
    hal::tick_lock();
    const bool todo = left_ != 0 && !next_ready_;
    hal::tick_unlock();
    if (!todo) {
        plan_left_ = 0;  // the path ended early (a stop): nothing more to plan
        return;
    }
    const uint8_t n = plan_left_ < plan_n_ ? (uint8_t)plan_left_ : plan_n_;
    const uint32_t acc = plan_acc_ + inc_ * n;
    const uint16_t after = (uint16_t)(plan_left_ - n);
    int16_t goal;
    int16_t ff;
    evaluate(acc, after, goal, ff);
    hal::tick_lock();
    if (left_ != 0) {  // a new move or a stop meanwhile would have reset the planning
        // The step toward `goal`, from where the setpoint will be when the tick takes this
        // segment: the present segment's steps still to go are fixed (seg_left_ <= kEvery), so
        // that point is known now, and the tick only copies the step (no multiply in it).
        int32_t at = pos8_;
        for (uint8_t k = seg_left_; k != 0; --k) at += step8_;
        next_step8_ = (fx::int24)fx::mul_q16((int32_t)goal * 256 - at, kRecip[n]);
        next_ff_ = ff;
        next_len_ = n;
        next_ready_ = 1;
        plan_acc_ = acc;
        plan_left_ = after;
        plan_n_ = kEvery;
    }
    hal::tick_unlock();
}

// About the middle, x = tau - 1/2 in [-1/2, 1/2], the profile is odd (with its offset) and
// its derivatives even and odd, which takes the fewest multiplies: nine, each 16 x 16 with
// the high word of the product kept (a byte move: no shifts by odd amounts, which the AVR
// does a bit at a time). Magnitudes in Q16, the signs of the odd terms apart.
//   s        = 1/2 + 15/8 x - 5 x^3 + 6 x^5
//   s'/1.875 = 16 w^2                 w = tau (1 - tau) = 1/4 - x^2
//   s''/5.77 = -(120 / 5.7735) x w = -20.785 x w
void Path::evaluate(uint32_t acc, uint16_t left_after, int16_t& goal, int16_t& ff) const {
    if (left_after == 0) {  // the path's end, at rest
        goal = end_;
        ff = 0;
    } else {
        const uint16_t t = hi16(acc);  // tau, Q16
        const bool first_half = t < 32768u;     // x < 0
        const uint16_t ax = first_half ? (uint16_t)(32768u - t) : (uint16_t)(t - 32768u);
        const uint16_t x2 = hi16(fx::mul_uu(ax, ax));  // <= 1/4
        const uint16_t x3 = hi16(fx::mul_uu(x2, ax));  // <= 1/8
        const uint16_t x5 = hi16(fx::mul_uu(x3, x2));  // <= 1/32
        // |s - 1/2| = 15/8 |x| - 5 |x|^3 + 6 |x|^5 <= 1/2
        const uint16_t g = (uint16_t)(2u * ax - (ax >> 3) - 5u * x3 + 6u * x5);
        // (g may pass 1/2 by a few counts of rounding at the very ends)
        uint16_t sv;
        if (first_half) {
            sv = g >= 32768u ? (uint16_t)0 : (uint16_t)(32768u - g);
        } else {
            sv = g >= 32768u ? (uint16_t)65535u : (uint16_t)(32768u + g);
        }
        goal = (int16_t)(start_ + (int16_t)((fx::mul_su(delta_, sv) + 32768L) >> 16));
        const uint16_t w = (uint16_t)(16384u - x2);  // tau (1 - tau) <= 1/4
        const uint16_t w2 = hi16(fx::mul_uu(w, w));  // <= 1/16
        const uint16_t vn = w2 >= 4096u ? (uint16_t)65535u : (uint16_t)(w2 << 4);
        const uint16_t xw = hi16(fx::mul_uu(ax, w));        // <= 0.0481
        const uint16_t a32 = hi16(fx::mul_uu(xw, 42566u));  // 20.785 |x| w / 32
        const uint16_t amag = a32 >= 2048u ? (uint16_t)65535u : (uint16_t)(a32 << 5);
        int16_t fv = (int16_t)(fx::mul_su(cv_, vn) >> 16);
        const int16_t fa = (int16_t)(fx::mul_su(ca_, amag) >> 16);
        // s'' > 0 in the first half (speeding up), < 0 in the second
        ff = first_half ? fx::sat_add16(fv, fa) : fx::sat_add16(fv, (int16_t)-fa);
    }
}

}  // namespace path
}  // namespace utrf
