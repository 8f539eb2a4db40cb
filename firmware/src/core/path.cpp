#include "path.h"

#include <math.h>

namespace utrf {
namespace path {

namespace {
int16_t q15(float duty) {
    return fx::sat16(fx::round_sat(duty * 32768.0f));
}

// 65536 / n for the steps toward the point n ticks ahead (n <= kEvery).
const uint16_t kRecip[kEvery + 1] = {0, 65535u, 32768u, 21845u, 16384u, 13107u};

inline uint16_t hi16(uint32_t v) { return (uint16_t)(v >> 16); }
}  // namespace

float min_duration(float distance_rad, const config::Motion& m) {
    const float d = fabsf(distance_rad);
    const float tv = kPeakSpeed * d / m.max_speed;
    const float ta = sqrtf(kPeakAccel * d / m.max_accel);
    return tv > ta ? tv : ta;
}

Plan plan(float distance_rad, float duration_s, int16_t end_bu, const config::Motion& m,
          float dt_s) {
    Plan p;
    p.end = end_bu;
    const float t_min = min_duration(distance_rad, m);
    float t = duration_s;
    p.stretched = false;
    if (!(t > 0.0f)) {
        t = t_min;
    } else if (t_min > t + 0.5f * dt_s) {  // within half a tick of the request is no stretch
        t = t_min;
        p.stretched = true;
    }
    float n = ceilf(t / dt_s - 1e-3f);
    if (n < 1.0f) n = 1.0f;
    if (n > 65535.0f) n = 65535.0f;
    p.ticks = (uint16_t)n;
    p.inc = 0xFFFFFFFFUL / p.ticks;
    const float tr = (float)p.ticks * dt_s;
    p.cv = q15(m.kv * distance_rad * kPeakSpeed / tr);
    p.ca = q15(m.ka * distance_rad * kPeakAccel / (tr * tr));
    return p;
}

void Path::start(const Plan& p, int16_t from_bu) {
    start_ = from_bu;
    end_ = p.end;
    delta_ = (int16_t)(p.end - from_bu);  // both within +-pi: fits
    inc_ = p.inc;
    cv_ = p.cv;
    ca_ = p.ca;
    acc_ = 0;
    pos8_ = (int32_t)from_bu << 8;
    step8_ = 0;  // until the finger's first turn (at most kEvery - 1 ticks: still at rest)
    ff_ = 0;
    left_ = p.ticks;
}

int16_t Path::tick(int16_t& target, bool turn) {
    if (UTRF_UNLIKELY(turn)) evaluate();
    acc_ += inc_;
    if (--left_ == 0) {  // the end: exactly there, at rest
        target = end_;
        ff_ = 0;
        return 0;
    }
    pos8_ += step8_;
    target = (int16_t)(pos8_ >> 8);
    return ff_;
}

void Path::evaluate() {
    // The point n ticks ahead: the end once the path has no more than kEvery ticks to go.
    uint8_t n;
    int16_t goal;
    if (left_ <= kEvery) {
        n = (uint8_t)left_;
        goal = end_;
        ff_ = 0;
    } else {
        n = kEvery;
        // tau in Q16; u = 1 - tau (65535 - t: one count short of exact, 1.5e-5).
        const uint16_t t = hi16(acc_ + (uint32_t)kEvery * inc_);
        const uint16_t u = (uint16_t)(65535u - t);
        const uint16_t t2 = hi16(fx::mul_uu(t, t));
        const uint16_t t3 = hi16(fx::mul_uu(t2, t));
        // s / 16 = t^3 (10 - 15 t + 6 t^2) / 16: the bracket / 16 lies in [1/16, 10/16], Q16.
        const uint16_t inner = (uint16_t)(40960u - hi16(fx::mul_uu(t, 61440u)) +
                                          hi16(fx::mul_uu(t2, 24576u)));
        const uint16_t s16 = hi16(fx::mul_uu(t3, inner));  // s / 16, Q16: <= 4096
        const uint16_t s = s16 >= 4096u ? (uint16_t)65535u : (uint16_t)(s16 << 4);
        goal = (int16_t)(start_ + (int16_t)((fx::mul_su(delta_, s) + 32768L) >> 16));
        // speed / peak = 16 (t u)^2; acceleration / peak = 10.392 t u (1 - 2t).
        const uint16_t w = hi16(fx::mul_uu(t, u));  // <= 16384
        const uint16_t w2 = hi16(fx::mul_uu(w, w));  // <= 4096
        const uint16_t vn = w2 >= 4096u ? (uint16_t)65535u : (uint16_t)(w2 << 4);
        const int16_t z = (int16_t)((int16_t)(u >> 1) - (int16_t)(t >> 1));  // 1 - 2t, Q15
        const int16_t pz = (int16_t)(fx::mul_su(z, w) >> 16);  // t u (1 - 2t), Q15
        // x 10.392 / 16 (Q16 42566), then x 16 as Q16 magnitude: (|an| << 5)
        const int16_t an16 = (int16_t)(fx::mul_su(pz, 42566u) >> 16);  // an / 16, Q15
        const bool neg = an16 < 0;
        const uint16_t amag16 = (uint16_t)(neg ? -an16 : an16);
        const uint16_t amag = amag16 >= 2048u ? (uint16_t)65535u : (uint16_t)(amag16 << 5);
        int32_t ff = fx::mul_su(cv_, vn) >> 16;
        const int32_t fa = fx::mul_su(ca_, amag) >> 16;
        ff = neg ? ff - fa : ff + fa;
        ff_ = fx::sat16(ff);
    }
    const int32_t diff8 = ((int32_t)goal << 8) - pos8_;
    step8_ = fx::mul_q16(diff8, kRecip[n]);
}

}  // namespace path
}  // namespace utrf
