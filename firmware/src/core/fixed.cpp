#include "fixed.h"

namespace utrf {
namespace fx {

int32_t round_sat(float v) {
    if (!(v == v)) return 0;  // NaN
    if (v >= 2147483520.0f) return 2147483647L;
    if (v <= -2147483520.0f) return -2147483647L;
    return (int32_t)(v < 0 ? v - 0.5f : v + 0.5f);
}

SatGain make_sat_gain(float coef, int32_t ymax) {
    SatGain g;
    g.coef = round_sat(coef);
    if (g.coef < 0) g.coef = 0;  // gains are never negative (validated at the protocol)
    g.ymax = ymax;
    g.xlim = g.coef == 0 ? 2147483647L : ymax / g.coef;
    return g;
}

}  // namespace fx
}  // namespace utrf
