// Joint-2 encoders: the AS5600 analog driver's checks and the reading-to-angle map.
//
// The hardware layer samples; this module judges the samples, so the rules are host-tested.
// Another sensor (AS5600 over I2C behind a TCA9548A, AS5048A over SPI) is a different driver
// producing the same hal::EncoderReading: a one-turn fraction and a status.
#ifndef UTRF_CORE_ENCODER_H
#define UTRF_CORE_ENCODER_H

#include <stdint.h>

#include "../hal/hal.h"

namespace utrf {
namespace encoder {

// AS5600 in analog mode drives 10 % of its supply at 0 degrees and 90 % at 360. The ADC uses
// the same 5 V as reference, so the reading is ratiometric: count = 1024 * (0.1 + 0.8 * turn).
// Valid band: 10-90 % with 1 % (10 counts) of tolerance each side for divider and ADC errors.
static const uint16_t kAdcBandLow = 92;
static const uint16_t kAdcBandHigh = 932;
// A channel whose sample counter has not moved for this many ticks has stopped (NO_DATA).
static const uint8_t kStaleTicks = 3;

// One AS5600 analog channel. The ADC interrupt keeps the two latest samples and a counter;
// the tick hands them here once per tick.
class As5600Analog {
   public:
    As5600Analog() : last_seq_(0), stale_(0) {}
    hal::EncoderReading update(uint16_t newest, uint16_t previous, uint8_t seq);

   private:
    uint8_t last_seq_;
    uint8_t stale_;
};

// Joint-2 angle in AU (1e-4 rad) from a one-turn reading: the reading minus the reading at
// angle 0, wrapped to +-half a turn, with the sign flipped for an encoder mounted to count
// against flexion.
inline int32_t angle_au(uint16_t turn, uint16_t zero_turn, bool invert) {
    int32_t d = (int16_t)(uint16_t)(turn - zero_turn);
    if (invert) d = -d;
    // 2 pi 1e4 / 65536 = 0.958738 AU per turn count; 62832 / 65536 = 0.958740.
    return (d * 62832L + 32768L) >> 16;
}

// Angle (rad) <-> one-turn count, for configuration (loop() context).
uint16_t turn_from_rad(float rad);
float rad_from_turn(uint16_t turn);

}  // namespace encoder
}  // namespace utrf

#endif  // UTRF_CORE_ENCODER_H
