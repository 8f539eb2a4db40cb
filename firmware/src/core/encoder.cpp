#include "encoder.h"

#include <math.h>

namespace utrf {
namespace encoder {

uint16_t turn_from_rad(float rad) {
    const float two_pi = 6.28318531f;
    float t = fmodf(rad, two_pi);
    if (t < 0) t += two_pi;
    long c = lroundf(t / two_pi * 65536.0f);
    return (uint16_t)(c & 0xFFFF);
}

float rad_from_turn(uint16_t turn) { return (float)turn * (6.28318531f / 65536.0f); }

}  // namespace encoder
}  // namespace utrf
