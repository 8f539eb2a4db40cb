#include "fixed.h"

#include <math.h>

namespace utrf {
namespace fx {

int32_t round_sat(float v) {
    if (!(v == v)) return 0;  // NaN
    if (v >= 2147483520.0f) return 2147483647L;
    if (v <= -2147483520.0f) return -2147483647L;
    return (int32_t)(v < 0 ? v - 0.5f : v + 0.5f);
}

int16_t bu(float rad) {
    return (int16_t)clamp32(round_sat(rad * kBuPerRad), -kBuHalfTurn, kBuHalfTurn - 1);
}

Gain make_gain(float value, int32_t ymax) {
    Gain g;
    g.m = 0;
    g.shift = 0;
    g.xlim = 32767;
    g.xspan = 65534u;
    if (!(value > 0.0f)) return g;
    // The smallest exponent whose mantissa still fits 16 bits keeps the most precision.
    for (int8_t s = -16; s <= 16; s = (int8_t)(s + 8)) {
        const float m = ldexpf(value, -s);
        if (m < 65535.5f || s == 16) {
            g.shift = s;
            g.m = m >= 65535.0f ? (uint16_t)65535u : (uint16_t)(m + 0.5f);
            break;
        }
    }
    if (g.m == 0) return g;
    // The largest |x| whose product stays within ymax.
    const float lim = (float)ymax / gain_value(g);
    g.xlim = lim >= 32767.0f ? (int16_t)32767 : (int16_t)lim;
    g.xspan = (uint16_t)(2u * (uint16_t)g.xlim);
    return g;
}

float gain_value(const Gain& g) { return ldexpf((float)g.m, g.shift); }

}  // namespace fx
}  // namespace utrf
