#include "encoder.h"

#include <math.h>

namespace utrf {
namespace encoder {

hal::EncoderReading As5600Analog::update(uint16_t newest, uint16_t previous, uint8_t seq) {
    hal::EncoderReading r;
    // Mean of the two samples, as a turn fraction: (a + b) / 2 mapped from 102.4..921.6 counts
    // to 0..65536, i.e. (a + b) * 40 - 8192, modulo 2^16.
    r.turn = (uint16_t)((uint16_t)(newest + previous) * 40u - 8192u);
    if (seq == last_seq_) {
        if (stale_ < kStaleTicks) ++stale_;
    } else {
        stale_ = 0;
        last_seq_ = seq;
    }
    if (stale_ >= kStaleTicks) {
        r.status = hal::EncoderStatus::NO_DATA;
    } else if (newest < kAdcBandLow || newest > kAdcBandHigh || previous < kAdcBandLow ||
               previous > kAdcBandHigh) {
        r.status = hal::EncoderStatus::OUT_OF_BAND;
    } else {
        r.status = hal::EncoderStatus::OK;
    }
    return r;
}

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
